"""Finger (dm_control ``finger-spin`` by default): a two-link planar finger spinning a hinged body.

Geometry features (``limb_length_0/1``, ``spinner_length``, ``spinner_radius``) change body
positions, geom sizes, sites and the masses that follow from them, so the model is recompiled from
the stock XML, edited, whenever (and only when) the geometry differs from the loaded one; every
other feature is written in place on top. A geometry where the finger cannot reach the spinner is
refused with a clear error.

The stock model disables gravity (``<flag gravity="disable"/>``): ``gravity`` defaults to 0, the
stock state, and a positive value turns the flag on, so gravity pulls the finger and the spinner.
Features that cannot act here: ``DmcFinger.left_out``.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ElementTree

import numpy as np
from dm_control.suite import finger as stock_finger

from contextrl.context.features import ContextBase, ContextError, context_type, feature
from contextrl.envs.dmc import base

GEOMETRY = ("limb_length_0", "limb_length_1", "spinner_length", "spinner_radius")
HINGE_DISTANCE = 0.4  # between the finger's and the spinner's hinges (stock body positions)
FINGERTIP_EXTRA = 0.01 + 0.001 + 0.03  # gap to the distal link, fingertip overhang and radius


@context_type
class DmcFingerContext(ContextBase):
    """Context features of the dm_control Finger; the defaults are the stock model."""

    gravity: float = base.gravity_feature(0.0)
    friction_tangential: float = base.friction_tangential_feature()
    timestep: float = base.timestep_feature(0.01)
    joint_damping: float = base.joint_damping_feature()
    actuator_strength: float = base.actuator_strength_feature()
    geom_density: float = base.geom_density_feature()
    density: float = base.density_feature()
    viscosity: float = base.viscosity_feature()
    wind_x: float = base.wind_feature("x")
    wind_z: float = base.wind_feature("z")
    limb_length_0: float = feature(0.17, 0.01, 0.2, unit="m", doc="length of the proximal link")
    limb_length_1: float = feature(0.16, 0.01, 0.2, unit="m", doc="length of the distal link")
    spinner_length: float = feature(
        0.18,
        0.01,
        0.4,
        unit="m",
        doc="length of the spinner's capsules",
        affects=("dynamics", "goal"),
    )
    spinner_radius: float = feature(
        0.04,
        0.01,
        0.05,
        unit="m",
        doc="radius of the spinner's capsules",
        affects=("dynamics", "goal"),
    )


def spinner_reach(length: float, radius: float) -> float:
    """Distance from the spinner's hinge to the farthest point of its two offset capsules."""
    return math.hypot(radius / 2, length / 2) + radius


def finger_reach(limb_length_0: float, limb_length_1: float) -> float:
    """Distance from the finger's hinge to the end of its fingertip, stretched out."""
    return limb_length_0 + limb_length_1 + FINGERTIP_EXTRA


def finger_xml(limb_length_0: float, limb_length_1: float, length: float, radius: float) -> str:
    """The stock finger XML with the geometry changed, keeping the stock proportions elsewhere."""
    xml, _ = stock_finger.get_model_and_assets()
    root = ElementTree.fromstring(xml)

    def find(tag: str, name: str) -> ElementTree.Element:
        return root.find(f".//{tag}[@name='{name}']")

    find("geom", "proximal").set("fromto", f"0 0 0 0 0 {-limb_length_0}")
    find("body", "distal").set("pos", f"0 0 {-(limb_length_0 + 0.01)}")
    find("geom", "distal").set("fromto", f"0 0 0 0 0 {-limb_length_1}")
    find("geom", "fingertip").set(
        "fromto", f"0 0 {-(limb_length_1 - 0.03)} 0 0 {-(limb_length_1 + 0.001)}"
    )
    find("site", "touchtop").set("pos", f".01 0 {-(limb_length_1 + 0.01)}")
    find("site", "touchbottom").set("pos", f"-.01 0 {-(limb_length_1 + 0.01)}")
    for name, side in (("cap1", 1), ("cap2", -1)):
        find("geom", name).set("size", f"{radius} {length / 2}")
        find("geom", name).set("pos", f"{side * radius / 2} 0 0")
    find("site", "tip").set("pos", f"0 0 {length / 2 + radius}")
    return ElementTree.tostring(root, encoding="unicode")


class DmcFinger(base.DmcEnv):
    """Finger on MuJoCo; tasks ``spin`` (default), ``turn_easy``, ``turn_hard``; 20 ms control."""

    domain = "finger"
    default_task = "spin"
    context_type = DmcFingerContext
    left_out = {
        "joint_stiffness": "the stock stiffness is 0",
        "wind_y": "the finger moves in the x-z plane",
        "torsional and rolling friction": "contacts have condim 3",
    }

    def __init__(self, task: str | None = None, **kwargs):
        super().__init__(task, **kwargs)
        self._stock_geometry = tuple(
            float(np.float32(self.context_space.features[n].default)) for n in GEOMETRY
        )  # as a context holds them (float32), so the default never triggers a recompile
        self._geometry = self._stock_geometry

    def _appliers(self) -> set[str]:
        return super()._appliers() | set(GEOMETRY)

    def _check_combination(self, values: dict[str, float]) -> None:
        reach = finger_reach(values["limb_length_0"], values["limb_length_1"])
        needed = HINGE_DISTANCE - spinner_reach(values["spinner_length"], values["spinner_radius"])
        if reach <= needed:
            raise ContextError(
                f"{self.name}: the finger cannot reach the spinner: limb_length_0 + limb_length_1 "
                f"= {values['limb_length_0'] + values['limb_length_1']:.3g} m reaches {reach:.3g} m, "
                f"the spinner's nearest point is {needed:.3g} m away; lengthen the limbs or the "
                f"spinner (spinner_length={values['spinner_length']:.3g}, "
                f"spinner_radius={values['spinner_radius']:.3g})"
            )

    def _apply_structure(self, values: dict[str, float]) -> None:
        geometry = tuple(values[n] for n in GEOMETRY)
        if geometry != self._geometry:
            xml, assets = stock_finger.get_model_and_assets()
            if geometry != self._stock_geometry:
                xml = finger_xml(*geometry)
            self._physics.reload_from_xml_string(xml, assets)
            self._capture_stock()  # the new geometry's masses are the base of geom_density
            self._applied = {}
            self._geometry = geometry
        super()._apply_structure(values)
