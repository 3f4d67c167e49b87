"""Systems: the only place behaviour lives. Each is an esper processor run once a frame."""
from systems.fly_camera_system import FlyCameraSystem, Input
from systems.portal_travel_system import PortalCrossing, PortalCrossings, PortalTravelSystem
from systems.present_system import PresentSystem
from systems.render_system import Output, RenderSystem
from systems.transform_system import TransformSystem

__all__ = [
    "FlyCameraSystem", "Input", "Output", "PortalCrossing", "PortalCrossings", "PortalTravelSystem", "PresentSystem",
    "RenderSystem", "TransformSystem",
]
