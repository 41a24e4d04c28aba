"""Physically based simulator: ToF camera, reflector target, three-axis turntable."""

from tofpose.sim.render import SensorModel, render_frame
from tofpose.sim.scene import TargetScene

__all__ = ["SensorModel", "TargetScene", "render_frame"]
