"""Fish (dm_control ``fish-swim`` by default): a fish swimming in a dense medium towards a target.

The stock model disables gravity and every constraint (no contacts, no limits) and sets the medium
density to 5000 kg/m³. Friction cannot act (``DmcFish.left_out``). ``gravity`` defaults to 0 (the stock
disabled state); a positive value enables it and the fish sinks.

This 30-gram fish in a dense medium is the stiffest of the family for MuJoCo's explicit fluid forces,
so three bounds are tighter than elsewhere, each where 300 random steps stayed stable: ``wind_*`` (a
current of the medium) within ±0.3 m/s, ``viscosity`` up to 2, ``geom_density`` from 0.5. A
``timestep`` of 0.04 or more still diverges (the episode then ends; see ``base``).
"""

from __future__ import annotations

from contextrl.context.features import ContextBase, context_type
from contextrl.envs.dmc import base


@context_type
class DmcFishContext(ContextBase):
    """Context features of the dm_control Fish; the defaults are the stock model."""

    gravity: float = base.gravity_feature(0.0)
    timestep: float = base.timestep_feature(0.004)
    joint_damping: float = base.joint_damping_feature()
    joint_stiffness: float = base.joint_stiffness_feature()
    actuator_strength: float = base.actuator_strength_feature()
    geom_density: float = base.geom_density_feature(lower=0.5)
    density: float = base.density_feature(5000.0)
    viscosity: float = base.viscosity_feature(upper=2.0)
    wind_x: float = base.wind_feature("x", 0.3)
    wind_y: float = base.wind_feature("y", 0.3)
    wind_z: float = base.wind_feature("z", 0.3)


class DmcFish(base.DmcEnv):
    """Fish on MuJoCo; tasks ``upright`` and ``swim`` (default); 1000 control steps of 40 ms."""

    domain = "fish"
    default_task = "swim"
    context_type = DmcFishContext
    left_out = {
        "friction": "the fish touches nothing",
    }
