"""The constants MuJoCo derives from the masses when it loads a model (``mj_setConst``), recomputed for a
context's masses inside the compiled step.

MJX (and brax's generalized pipeline) read ``body_invweight0``, ``dof_invweight0`` and
``tendon_invweight0``, the mean inverse inertia each body, joint and tendon has at the initial pose, to
set how soft contacts, joint limits and tendon constraints are;
``body_subtreemass`` enters the subtree velocities. A system whose masses change keeps the stock values
unless they are recomputed, so contacts would still behave as if the stock masses were there.

At the initial pose the joint-space inertia is ``M = Σ_b m_b Jp_bᵀ Jp_b + Jr_bᵀ R_b diag(I_b) R_bᵀ Jr_b +
diag(armature)``, with ``Jp_b``/``Jr_b`` the body's Jacobians at its centre of mass and ``R_b`` its inertial
frame; none of these but ``m_b`` and ``I_b`` depends on the masses, so they are computed once per model
(with MuJoCo, on the host) and ``M`` is a sum of small arrays per context. Then, as ``mj_setConst``: a
body's weight is the mean diagonal of the translational and of the rotational block of ``J M⁻¹ Jᵀ``, a
joint's the mean diagonal of ``M⁻¹`` over its translational or rotational degrees of freedom, a
tendon's ``J M⁻¹ Jᵀ`` with its Jacobian ``J`` at the initial pose; a body
that moves without rotating (and its joints) weighs ``1 / mass``; bodies welded to the world nothing.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

MJ_MINVAL = 1e-15  # MuJoCo's mjMINVAL


@dataclasses.dataclass(frozen=True)
class PoseTables:
    """What the mass-derived constants need of a model at its initial pose, none of it mass-dependent."""

    jacobian: np.ndarray  # (nbody, 6, nv): translational, then rotational, at each body's COM
    frame: np.ndarray  # (nbody, 3, 3): each body's inertial frame in the world
    armature: np.ndarray  # (nv,)
    parent: np.ndarray  # (nbody,)
    moving: np.ndarray  # (nbody,) bool: not welded to the world
    simple: np.ndarray  # (nbody,) bool: moves without rotating (MuJoCo's weight there: 1 / mass)
    dof_body: np.ndarray  # (nv,): the body each dof moves
    dof_group: np.ndarray  # (nv,): dofs of one group share one weight (a free joint has two groups)
    tendon_jacobian: np.ndarray  # (ntendon, nv)


def pose_tables(model) -> PoseTables:
    """The tables of a MuJoCo model (``mujoco.MjModel``), computed once at ``qpos0``."""
    import mujoco

    data = mujoco.MjData(model)
    data.qpos[:] = model.qpos0
    mujoco.mj_fwdPosition(model, data)  # kinematics, centres of mass, tendons
    jacobian = np.zeros((model.nbody, 6, model.nv))
    for body in range(model.nbody):
        mujoco.mj_jacBodyCom(model, data, jacobian[body, :3], jacobian[body, 3:], body)
    dof_group = np.zeros(model.nv, np.int32)
    groups = 0
    for joint in range(model.njnt):
        start = int(model.jnt_dofadr[joint])
        kind = int(model.jnt_type[joint])
        if kind == mujoco.mjtJoint.mjJNT_FREE:  # translation, then rotation
            dof_group[start : start + 3], dof_group[start + 3 : start + 6] = groups, groups + 1
            groups += 2
        elif kind == mujoco.mjtJoint.mjJNT_BALL:
            dof_group[start : start + 3] = groups
            groups += 1
        else:
            dof_group[start] = groups
            groups += 1
    return PoseTables(
        jacobian=jacobian,
        frame=data.ximat.reshape(-1, 3, 3).copy(),
        armature=np.asarray(model.dof_armature, np.float64).copy(),
        parent=np.asarray(model.body_parentid).copy(),
        moving=np.asarray(model.body_weldid) != 0,
        simple=np.asarray(model.body_simple) == 2,
        dof_body=np.asarray(model.dof_bodyid).copy(),
        dof_group=dof_group,
        tendon_jacobian=tendon_jacobian(model, data),
    )


def tendon_jacobian(model, data) -> np.ndarray:
    """The tendons' Jacobian (ntendon, nv), dense (MuJoCo keeps it sparse)."""
    import mujoco

    dense = np.zeros((model.ntendon, model.nv))
    if model.ntendon:
        mujoco.mju_sparse2dense(
            dense, data.ten_J, model.ten_J_rownnz, model.ten_J_rowadr, model.ten_J_colind
        )
    return dense


def mass_constants(tables: PoseTables, mass: jax.Array, inertia: jax.Array) -> dict[str, jax.Array]:
    """``body_invweight0`` (nbody, 2), ``dof_invweight0`` (nv,), ``tendon_invweight0`` (ntendon,) and
    ``body_subtreemass`` (nbody,) for body masses ``mass`` (nbody,) and principal inertias ``inertia``
    (nbody, 3)."""
    translation, rotation = tables.jacobian[:, :3], tables.jacobian[:, 3:]
    world_inertia = jnp.einsum("bij,bj,bkj->bik", tables.frame, inertia, tables.frame)
    matrix = (
        jnp.einsum("b,bin,bim->nm", mass, translation, translation)
        + jnp.einsum("bin,bij,bjm->nm", rotation, world_inertia, rotation)
        + jnp.diag(jnp.asarray(tables.armature, mass.dtype))
    )
    inverse = jnp.linalg.inv(matrix)
    spatial = jnp.einsum("bin,nm,bjm->bij", tables.jacobian, inverse, tables.jacobian)
    diagonal = jnp.diagonal(spatial, axis1=1, axis2=2)  # (nbody, 6)
    body = jnp.stack([diagonal[:, :3].mean(-1), diagonal[:, 3:].mean(-1)], axis=-1)
    inverse_mass = 1.0 / jnp.maximum(MJ_MINVAL, mass)
    simple = jnp.stack([inverse_mass, jnp.zeros_like(mass)], axis=-1)
    body = jnp.where(tables.simple[:, None], simple, body)
    body = jnp.where(tables.moving[:, None], body, 0.0)
    groups = int(tables.dof_group.max()) + 1
    sums = jax.ops.segment_sum(jnp.diagonal(inverse), tables.dof_group, num_segments=groups)
    dof = (sums / np.bincount(tables.dof_group, minlength=groups))[tables.dof_group]
    dof = jnp.where(tables.simple[tables.dof_body], inverse_mass[tables.dof_body], dof)
    subtree = mass
    for body_id in range(len(tables.parent) - 1, 0, -1):
        subtree = subtree.at[tables.parent[body_id]].add(subtree[body_id])
    tendon = jnp.einsum("tn,nm,tm->t", tables.tendon_jacobian, inverse, tables.tendon_jacobian)
    return {
        "body_invweight0": body,
        "dof_invweight0": dof,
        "tendon_invweight0": tendon,
        "body_subtreemass": subtree,
    }
