"""Systems: the only place behaviour lives. Each is an esper processor run once a frame, in
the stage order of ``shell.app.FRAME_STAGES`` (ARCHITECTURE.md)."""
from systems.extract_system import ExtractSystem
from systems.fly_camera_system import FlyCameraSystem
from systems.main_view_system import MainViewSystem
from systems.portal_travel_system import PortalTravelSystem
from systems.prepare_system import PrepareSystem
from systems.present_system import PresentSystem
from systems.reflection_system import ReflectionSystem
from systems.transform_system import TransformSystem

__all__ = [
    "ExtractSystem", "FlyCameraSystem", "MainViewSystem", "PortalTravelSystem",
    "PrepareSystem", "PresentSystem", "ReflectionSystem", "TransformSystem",
]
