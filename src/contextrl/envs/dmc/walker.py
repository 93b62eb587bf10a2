"""Walker (dm_control ``walker-walk`` by default): a planar biped that stands, walks or runs.

Features that cannot act here are listed, with why, in ``DmcWalker.left_out``.
"""

from __future__ import annotations

from contextrl.context.features import ContextBase, context_type
from contextrl.envs.dmc import base


@context_type
class DmcWalkerContext(ContextBase):
    """Context features of the dm_control Walker; the defaults are the stock model."""

    gravity: float = base.gravity_feature()
    friction_tangential: float = base.friction_tangential_feature()
    timestep: float = base.timestep_feature(0.0025)
    joint_damping: float = base.joint_damping_feature()
    actuator_strength: float = base.actuator_strength_feature()
    geom_density: float = base.geom_density_feature()
    density: float = base.density_feature()
    viscosity: float = base.viscosity_feature()
    wind_x: float = base.wind_feature("x")
    wind_z: float = base.wind_feature("z")


class DmcWalker(base.DmcEnv):
    """Walker on MuJoCo; tasks ``stand``, ``walk`` (default), ``run``; 1000 control steps of 25 ms."""

    domain = "walker"
    default_task = "walk"
    context_type = DmcWalkerContext
    left_out = {
        "joint_stiffness": "every stock stiffness is 0, so a scale of it is 0",
        "wind_y": "the walker moves in the x-z plane; a wind across it exerts no force on any degree of freedom",
        "torsional and rolling friction": "the walker's contacts have condim 3, which has only sliding friction",
    }
