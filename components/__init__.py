"""Components: plain data attached to entities. Behaviour lives in ``systems``."""
from components.ambient import AmbientOcclusion, ContactShadows, HemisphereLight
from components.camera import Camera, DirectionalLight, FlyController, PointLight
from components.clouds import CloudLayer
from components.decal import Decal, FromDecal
from components.detail import LevelOfDetail
from components.fog import Fog, FogVolume, VolumetricFog
from components.mirror import Mirror
from components.model import Animation, AnimationEvents, AnimationLayer, FromModel, Model
from components.monitor import Monitor
from components.particles import ParticleEmitter
from components.portal import Portal, PortalClone, Slice, Traveller
from components.pose import Morph, Skin
from components.post import (
    Bloom,
    ChromaticAberration,
    ColorGrading,
    DepthOfField,
    FilmGrain,
    LensFlare,
    MotionBlur,
    Tonemap,
    Vignette,
)
from components.probe import IrradianceVolume, ReflectionProbe
from components.rendering import Emissive, Material, MeshRef, Reflective, Refractive, Skybox
from components.ripples import Ripples, Splash, Wake
from components.screen import ScreenPanel, ScreenText
from components.screen_reflections import ScreenReflections
from components.time_of_day import TimeOfDay
from components.tracking import ComponentValueError, ComponentWarning, TrackedComponent
from components.transform import Transform, euler_rotation, look_rotation, yaw_pitch_of, yaw_pitch_rotation
from components.visibility import Visibility
from components.water import Water

__all__ = [
    "AmbientOcclusion", "Animation", "AnimationEvents", "AnimationLayer", "Bloom", "Camera", "ChromaticAberration",
    "CloudLayer",
    "ColorGrading",
    "ComponentValueError", "ContactShadows",
    "ComponentWarning", "Decal", "DepthOfField",
    "DirectionalLight", "Emissive", "FilmGrain", "FlyController", "Fog", "FogVolume", "FromDecal", "FromModel",
    "HemisphereLight",
    "IrradianceVolume",
    "LensFlare", "LevelOfDetail", "Material",
    "MeshRef", "Mirror", "Model", "Monitor", "Morph", "MotionBlur", "ParticleEmitter", "PointLight", "Portal",
    "PortalClone",
    "ReflectionProbe",
    "Reflective",
    "Refractive", "Ripples",
    "ScreenPanel", "ScreenReflections", "ScreenText", "Skin", "Skybox", "Slice", "Splash", "TimeOfDay",
    "Tonemap", "TrackedComponent", "Transform", "Traveller", "Vignette", "Visibility", "VolumetricFog", "Wake", "Water",
    "euler_rotation", "look_rotation", "yaw_pitch_of", "yaw_pitch_rotation",
]
