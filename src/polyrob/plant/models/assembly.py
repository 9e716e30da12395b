"""What every uncertainty model builds its plant from: the arm's fixed rows, the plant itself, its nominal.

Every model writes an arm ``ẋ = [q̇; q̈]`` whose upper rows are ``q̇`` and
whose output is ``y = q``; it differs only in the lower rows and in its
``Δ`` channels.  The pieces the models share are here so that each module
holds what is its own.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from polyrob.errors import ArgumentError, NotApplicable
from polyrob.plant.lftplant import UncertainPlant, weakest_enclosure

__all__ = [
    "check_nominal",
    "position_output",
    "into_accelerations",
    "arm_state_matrix",
    "normalised",
    "Channels",
    "enclosure_info",
    "model_plant",
    "at_pldi_nominal",
    "check_inverse_inertia_input",
]


def check_nominal(nominal: str) -> None:
    """Raise :class:`PolyrobError` unless ``nominal`` is ``"pldi"`` or ``"midpoint"``."""
    if nominal not in ("pldi", "midpoint"):
        raise ArgumentError(f"unknown nominal '{nominal}': use 'pldi' or 'midpoint'")


def position_output(m: int) -> np.ndarray:
    """``C = [I_m 0]``: the measured output is the joint positions."""
    return np.hstack([np.eye(m), np.zeros((m, m))])


def into_accelerations(m: int) -> np.ndarray:
    """``[0; I_m]`` (``2m x m``): what enters the arm's lower (acceleration) rows."""
    low = np.zeros((2 * m, m))
    low[m:] = np.eye(m)
    return low


def arm_state_matrix(lower_rows) -> np.ndarray:
    """``[0 I; lower_rows]``: the arm's state matrix with the given acceleration rows (``m x 2m``)."""
    lower_rows = np.asarray(lower_rows, float)
    m = lower_rows.shape[0]
    A = np.zeros((2 * m, 2 * m))
    A[:m, m:] = np.eye(m)
    A[m:] = lower_rows
    return A


def normalised(value, radius):
    """``value / radius`` where the radius is positive, 0 where a range has no width."""
    radius = np.asarray(radius, float)
    return np.where(radius > 0, value / np.where(radius > 0, radius, 1.0), 0.0)


@dataclass(frozen=True, eq=False)
class Channels:
    """The ``Δ`` channels of a model's LFT: ``ẋ += B_d d``, ``v = C_v x + D_vd d + D_vu u``.

    Attributes
    ----------
    B_d, C_v, D_vu : ndarray
    block_structure : array_like (n_blocks, 2)
        MATLAB ``blk`` rows, in channel order.
    names : sequence of str
        One per channel.
    parameter : sequence of int
        The parameter of each channel (-1: a full block's).
    D_vd : ndarray, optional
        Default zero.
    """

    B_d: np.ndarray
    C_v: np.ndarray
    D_vu: np.ndarray
    block_structure: object
    names: tuple
    parameter: object
    D_vd: np.ndarray | None = None


def enclosure_info(inputs: dict) -> dict:
    """``info`` entries of the plant's enclosure: the weakest of its ``inputs`` and the inputs themselves."""
    return {"enclosure": weakest_enclosure(*inputs.values()), "enclosure_inputs": dict(inputs)}


def model_plant(pldi, model: str, centre, channels: Channels, parameters, info: dict, **fields) -> UncertainPlant:
    """The :class:`UncertainPlant` of a model, its nominal at its LFT centre (``A_nom = A_mid``, ``δ_n = 0``).

    Parameters
    ----------
    pldi : PLDI
        Whose robot it is.
    model : str
        The model's name (``unc.model``).
    centre : (A_mid, B_mid)
        The LFT at ``Δ = 0``.
    channels : Channels
    parameters : (names, lower, upper)
        The real parameters and their physical ranges.
    info : dict
    **fields
        Any other field of the plant (``nominal_kind``, a box's
        ``channel_index``, ...); :func:`at_pldi_nominal` moves the nominal
        to the PLDI's afterwards.
    """
    A_mid, B_mid = centre
    names, lower, upper = parameters
    figures = {
        "nominal_kind": "pldi",
        "A_nom": A_mid,
        "B_nom": B_mid,
        "channel_index": None,
        "channel_lower": None,
        "channel_upper": None,
        "nominal_delta": np.zeros(len(names)),
        "offset": np.zeros(len(names)),
        **fields,
    }
    return UncertainPlant(
        robot_name=getattr(pldi, "robot_name", ""),
        model=model,
        C=position_output(np.asarray(B_mid).shape[1]),
        A_mid=A_mid,
        B_mid=B_mid,
        B_d=channels.B_d,
        C_v=channels.C_v,
        D_vu=channels.D_vu,
        D_vd=channels.D_vd,
        block_structure=np.asarray(channels.block_structure, int).reshape(-1, 2),
        channel_names=tuple(channels.names),
        channel_parameter=np.asarray(channels.parameter, int),
        parameter_names=tuple(names),
        parameter_lower=np.asarray(lower, float),
        parameter_upper=np.asarray(upper, float),
        info=info,
        **figures,
    )


def at_pldi_nominal(plant: UncertainPlant, pldi, nominal_delta, radius) -> UncertainPlant:
    """``plant`` with the PLDI's nominal ``(A0, B0)``, met at ``δ = nominal_delta`` (parameters of half-width ``radius``)."""
    nominal_delta = np.asarray(nominal_delta, float)
    return plant.with_figures(
        A_nom=np.asarray(pldi.A0, float),
        B_nom=np.asarray(pldi.B0, float),
        nominal_delta=nominal_delta,
        offset=-np.asarray(radius, float) * nominal_delta,
    )


def check_inverse_inertia_input(robot, domain, model: str) -> None:
    """Raise :class:`NotApplicable` unless ``B = [0; M(q)⁻¹]`` at a few points of the domain (no motor model in front)."""
    m = robot.m
    q, qd, u = domain.sample(16, method="uniform", seed=5)
    _, B = robot.jacobians_batch(q, qd, u)
    Ms = np.array([robot.mass_matrix(qq) for qq in q])
    if np.abs(B[:, :m]).max() > 0 or np.abs(Ms @ B[:, m:, :] - np.eye(m)).max() > 1e-8:
        raise NotApplicable(f"{robot.name}: B is not [0; M(q)^-1]; the {model} model does not apply")
