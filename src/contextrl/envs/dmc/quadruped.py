"""Quadruped (dm_control ``quadruped-walk`` by default): a four-legged ant walking in 3-D.

Features that cannot act here: ``DmcQuadruped.left_out``. Actuators are filtered
position servos, so ``actuator_strength`` scales their gain and bias (see ``base``).
"""

from __future__ import annotations

from contextrl.context.features import ContextBase, context_type
from contextrl.envs.dmc import base


@context_type
class DmcQuadrupedContext(ContextBase):
    """Context features of the dm_control Quadruped; the defaults are the stock model."""

    gravity: float = base.gravity_feature()
    friction_tangential: float = base.friction_tangential_feature()
    timestep: float = base.timestep_feature(0.005)
    joint_damping: float = base.joint_damping_feature()
    actuator_strength: float = base.actuator_strength_feature()
    geom_density: float = base.geom_density_feature()
    density: float = base.density_feature()
    viscosity: float = base.viscosity_feature()
    wind_x: float = base.wind_feature("x")
    wind_y: float = base.wind_feature("y")
    wind_z: float = base.wind_feature("z")


class DmcQuadruped(base.DmcEnv):
    """Quadruped on MuJoCo; tasks ``walk`` (default), ``run``, ``escape``, ``fetch``; 20 ms control."""

    domain = "quadruped"
    default_task = "walk"
    context_type = DmcQuadrupedContext
    left_out = {
        "joint_stiffness": "every stock stiffness is 0",
        "torsional and rolling friction": "the body's contacts have condim 1 or 3; only the fetch ball has condim 6",
    }
