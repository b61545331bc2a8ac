"""Special-relativistic kinematics of the camera.

Provides
--------
==============================  ==============================================================
``gamma(beta)``                 Lorentz factor γ = 1/sqrt((1-b)(1+b))
``speed(beta)``                 b = |β|, overflow/underflow-safe
``rapidity(beta)``              φ = atanh(b)
``lorentz_boost(beta)``         the (4, 4) boost lab -> frame moving with β
``aberrate(d_cam, beta)``       camera-frame viewing direction -> lab viewing direction
``aberrate_inverse(d_lab, β)``  lab viewing direction -> camera-frame viewing direction
``doppler_factor(d_cam, beta)`` D = ν_cam/ν_lab from a camera-frame direction
``doppler_factor_lab(d_lab, β)`` D from a lab-frame direction
``doppler_ring_angle(b)``       camera-frame angle of the D = 1 ring
``ShutterEvent``                lab event, velocity and proper time of a frame's shutter
``snapshot_event``              shutter event of a camera that moved at constant β since τ = 0
``constant_acceleration_event`` shutter event under constant proper acceleration
``integrate_worldline``         RK4 (= Simpson) integration of an arbitrary β(τ)
``worldline_events``            the shutter event of every frame of an animation
``check_beta``                  validate a user-supplied β, raising ``UserError``
==============================  ==============================================================

Conventions (see physics.md, the design's authority on formulas and signs)
--------------------------------------------------------------------------
- c = 1. Times are ``ct`` in scene units.
- **Lab frame S**: static scene objects are at rest. **Camera frame S'**: moves with
  velocity β (a 3-vector in *lab axes*), |β| < 1, obtained from S by a *pure boost*
  (no rotation), so S' uses the lab axes.
- Viewing directions ``d_cam`` (d') and ``d_lab`` (d) are unit vectors pointing *into the
  scene* (opposite to the photon's propagation). We trace backwards along ``d_lab``.
- Doppler factor D = ν_cam/ν_lab; λ_lab = D·λ_cam. D > 1 looking ahead.
- Everything is float64. Functions taking directions broadcast over leading axes
  (``(..., 3)``); β is one 3-vector per call there. ``gamma``, ``speed``, ``rapidity`` and
  ``lorentz_boost`` also broadcast over leading axes of β.
- Near b = 1 the precision of anything is limited by how b itself is stored:
  a 3-vector β fixes 1 - b only to about one ulp of 1 (1.1e-16) absolute. Every formula
  here avoids *additional* cancellation (no 1 - b², no 1 - β·d' computed directly).

Functions are pure: no global state, inputs never modified. Invalid arguments raise
``ValueError``; user input goes through :func:`check_beta`, which raises
:class:`~relray.core.errors.UserError`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from ..errors import UserError
from ..jit import njit

__all__ = [
    "ShutterEvent",
    "aberrate",
    "aberrate_inverse",
    "check_beta",
    "constant_acceleration_event",
    "doppler_factor",
    "doppler_factor_lab",
    "doppler_ring_angle",
    "gamma",
    "integrate_worldline",
    "lorentz_boost",
    "rapidity",
    "snapshot_event",
    "speed",
    "worldline_events",
]

#: Default number of RK4 steps of :func:`integrate_worldline`.
DEFAULT_RK4_STEPS = 256


# --------------------------------------------------------------------------- helpers


def _scalar_or_array(x: np.ndarray) -> float | np.ndarray:
    """Return a Python float for a 0-d result, the array otherwise."""
    return float(x) if np.ndim(x) == 0 else x


def _as_vectors(beta: ArrayLike, name: str = "beta") -> np.ndarray:
    """``beta`` as a float64 array of shape (..., 3); raise ValueError otherwise."""
    arr = np.asarray(beta, dtype=np.float64)
    if arr.ndim == 0 or arr.shape[-1] != 3:
        raise ValueError(f"{name} must have shape (..., 3), got {arr.shape}")
    return arr


def _as_vector3(v: ArrayLike, name: str) -> np.ndarray:
    """``v`` as a finite float64 array of shape (3,); raise ValueError otherwise."""
    arr = np.asarray(v, dtype=np.float64)
    if arr.shape != (3,):
        raise ValueError(f"{name} must have shape (3,), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite, got {arr.tolist()}")
    return arr


def _checked_speed(beta: ArrayLike) -> np.ndarray:
    """b = |β| as an array (0-d for a scalar or a single 3-vector), validated 0 <= b < 1.

    A 0-d ``beta`` is a speed; any other array is read as (..., 3) velocity vectors.
    """
    arr = np.asarray(beta, dtype=np.float64)
    if not np.all(np.isfinite(arr)):
        raise ValueError("beta must be finite")
    b = np.abs(arr) if arr.ndim == 0 else _hypot3(_as_vectors(arr))
    if np.any(b >= 1.0):
        raise ValueError(f"|beta| = {float(np.max(b))!r} must be below 1 (the speed of light)")
    return b


def _hypot3(v: np.ndarray) -> np.ndarray:
    """|v| over the last axis without overflow or underflow: hypot(hypot(x, y), z)."""
    return np.hypot(np.hypot(v[..., 0], v[..., 1]), v[..., 2])


def _unit(v: np.ndarray) -> np.ndarray:
    """v/|v| for a non-zero 3-vector, accurate even for subnormal components.

    Dividing by |v| directly fails there: |(0, 5e-324, 5e-324)| rounds to 5e-324 and
    v/|v| = (0, 1, 1). Scaling by the largest component first avoids this.
    """
    u = v / np.max(np.abs(v))
    return u / _hypot3(u)


def _inv_gamma(b: np.ndarray | float) -> np.ndarray:
    """1/γ = sqrt((1-b)(1+b)) for a speed b in [0, 1); 1-b is exact for b >= 1/2."""
    return np.sqrt((1.0 - b) * (1.0 + b))


def _one_minus_dot(d: np.ndarray, beta_hat: np.ndarray, b: float) -> np.ndarray:
    """1 - b (β̂·d) for unit d, without cancellation.

    1 - b cos θ = (1 - b) + b (1 - cos θ), and 1 - cos θ = |d - β̂|²/2 (half the squared
    chord). Both terms are non-negative, so the sum keeps full relative precision even
    when b -> 1 and d -> β̂. The chord form is also insensitive, to first order, to
    |d| differing from 1 by rounding: it returns the value of the normalised direction.
    """
    chord = d - beta_hat
    return (1.0 - b) + b * (0.5 * np.sum(chord * chord, axis=-1))


def _sinhc(x: float) -> float:
    """sinh(x)/x, equal to 1 at x = 0 (no division by a vanishing x)."""
    return math.sinh(x) / x if x != 0.0 else 1.0


# --------------------------------------------------------------------------- γ, b, φ, Λ


def speed(beta: ArrayLike) -> float | np.ndarray:
    """Speed b = |β| (no validation).

    ``beta``: a scalar speed (returns |beta|) or velocities of shape (..., 3), any frame.
    Computed as hypot(hypot(βx, βy), βz): no overflow or underflow of the squares,
    so b = 1e-300 is returned as 1e-300, not 0.
    """
    arr = np.asarray(beta, dtype=np.float64)
    if arr.ndim == 0:
        return float(np.abs(arr))
    return _scalar_or_array(_hypot3(_as_vectors(arr)))


def gamma(beta: ArrayLike) -> float | np.ndarray:
    """Lorentz factor γ = 1/sqrt((1-b)(1+b)), b = |β|.

    ``beta``: a scalar speed, a 3-vector, or (..., 3) vectors (lab axes). Returns a float
    for a scalar or a single 3-vector, an array of shape (...) otherwise.
    The factored form keeps full precision near b = 1, where 1 - b² would cancel.
    Raises ValueError if any |β| >= 1 or any component is non-finite.
    """
    return _scalar_or_array(1.0 / _inv_gamma(_checked_speed(beta)))


def rapidity(beta: ArrayLike) -> float | np.ndarray:
    """Rapidity φ = atanh(b), b = |β| (so γ = cosh φ, γb = sinh φ).

    ``beta``: as for :func:`gamma`. Raises ValueError if |β| >= 1 or non-finite.
    """
    return _scalar_or_array(np.arctanh(_checked_speed(beta)))


def lorentz_boost(beta: ArrayLike) -> np.ndarray:
    """Boost matrix Λ from lab coordinates (ct, x, y, z) to a frame moving with β.

        Λ00 = γ,   Λ0i = Λi0 = -γ βi,   Λij = δij + γ²/(γ+1) βi βj

    ``beta``: lab velocity of the target frame, shape (3,) or (..., 3). Returns (4, 4)
    or (..., 4, 4). (γ-1)/b² is written as γ²/(γ+1): no division by b², and β = 0
    gives exactly the identity (no -0.0 entries either). The inverse is Λ(-β).
    Raises ValueError if |β| >= 1.
    """
    v = _as_vectors(beta)
    g = np.asarray(1.0 / _inv_gamma(_checked_speed(v)))
    k = g * g / (g + 1.0)
    out = np.zeros(v.shape[:-1] + (4, 4))
    out[..., 0, 0] = g
    mixed = 0.0 - g[..., None] * v  # 0.0 - x turns -0.0 into +0.0
    out[..., 0, 1:] = mixed
    out[..., 1:, 0] = mixed
    out[..., 1:, 1:] = np.eye(3) + k[..., None, None] * (v[..., :, None] * v[..., None, :])
    return out


# --------------------------------------------------------------------------- aberration


def aberrate(d_cam: ArrayLike, beta: ArrayLike) -> np.ndarray:
    """Camera-frame viewing directions -> lab viewing directions (trace backwards along these).

        d = [ d'/γ + β (γ (β·d')/(γ+1) - 1) ] / (1 - β·d')

    ``d_cam``: unit viewing directions d' in the camera frame S', shape (3,) or (..., 3).
    ``beta``: camera velocity in the lab, shape (3,). Returns unit ``d_lab``, same shape.

    Evaluated in the algebraically equal, cancellation-free form: with cos θ' = β̂·d',
    the part of d along β̂ is proportional to cos θ' - b = (1 - b) - (1 - cos θ') and the
    part across it to d'_⊥/γ, where 1 - cos θ' = |d' - β̂|²/2 and
    d'_⊥ = c - (c·β̂) β̂ with the chord c = d' - β̂ (both accurate for d' near β̂, and
    d'_⊥ has no spurious component along β̂, which would be amplified by γ when
    cos θ' ≈ b). The positive common factor 1/(1 - β·d') drops out because the result
    is renormalised to unit length in float64.
    At β = 0 this returns a float64 copy of ``d_cam``, bit for bit.
    Raises ValueError if |β| >= 1.
    """
    d = _as_vectors(d_cam, "d_cam")
    v = _as_vector3(beta, "beta")
    b = float(_checked_speed(v))
    if b == 0.0:
        return d.copy()
    beta_hat = _unit(v)
    inv_g = _inv_gamma(b)
    chord = d - beta_hat
    one_minus_cos = 0.5 * np.sum(chord * chord, axis=-1, keepdims=True)
    d_perp = chord - np.sum(chord * beta_hat, axis=-1, keepdims=True) * beta_hat
    out = ((1.0 - b) - one_minus_cos) * beta_hat + inv_g * d_perp
    out /= np.sqrt(np.sum(out * out, axis=-1, keepdims=True))
    return out


def aberrate_inverse(d_lab: ArrayLike, beta: ArrayLike) -> np.ndarray:
    """Lab viewing directions -> camera-frame viewing directions; inverse of :func:`aberrate`.

        d' = [ d/γ + β (γ (β·d)/(γ+1) + 1) ] / (1 + β·d)  =  aberrate(d, -β)

    The map from S to S' is the map from S' to S with β -> -β (along β̂:
    cos θ' = (cos θ + b)/(1 + b cos θ); across: sin θ' = sin θ / (γ (1 + b cos θ))).
    ``d_lab``: unit lab viewing directions, (3,) or (..., 3); ``beta``: camera velocity
    in the lab, (3,). Returns unit ``d_cam``. Bit-exact identity at β = 0.
    """
    return aberrate(d_lab, -_as_vector3(beta, "beta"))


# --------------------------------------------------------------------------- Doppler


def doppler_factor(d_cam: ArrayLike, beta: ArrayLike) -> float | np.ndarray:
    """Doppler factor D = ν_cam/ν_lab = 1/(γ (1 - β·d')) of camera-frame viewing directions.

    ``d_cam``: unit viewing directions d' in the camera frame, (3,) or (..., 3).
    ``beta``: camera velocity in the lab, (3,). Returns D, a float or shape (...).
    1 - β·d' is computed as (1 - b) + b |d' - β̂|²/2, a sum of non-negative terms, so D
    keeps full relative precision as b -> 1 and d' -> β̂ (where D -> sqrt((1+b)/(1-b))).
    D = 1 exactly at β = 0.
    """
    d = _as_vectors(d_cam, "d_cam")
    v = _as_vector3(beta, "beta")
    b = float(_checked_speed(v))
    if b == 0.0:
        return _scalar_or_array(np.ones(d.shape[:-1]))
    return _scalar_or_array(1.0 / (_one_minus_dot(d, _unit(v), b) / _inv_gamma(b)))


def doppler_factor_lab(d_lab: ArrayLike, beta: ArrayLike) -> float | np.ndarray:
    """Doppler factor D = ν_cam/ν_lab = γ (1 + β·d) of lab-frame viewing directions.

    ``d_lab``: unit lab viewing directions d, (3,) or (..., 3); ``beta``: camera velocity
    in the lab, (3,). Returns D, a float or shape (...). Equals
    ``doppler_factor(d_cam, beta)`` for ``d_lab = aberrate(d_cam, beta)``.
    1 + β·d = (1 - b) + b |d + β̂|²/2 (no cancellation when looking backwards, d -> -β̂).
    D = 1 exactly at β = 0.
    """
    d = _as_vectors(d_lab, "d_lab")
    v = _as_vector3(beta, "beta")
    b = float(_checked_speed(v))
    if b == 0.0:
        return _scalar_or_array(np.ones(d.shape[:-1]))
    return _scalar_or_array(_one_minus_dot(d, -_unit(v), b) / _inv_gamma(b))


def doppler_ring_angle(b: ArrayLike) -> float | np.ndarray:
    """Camera-frame angle θ' (radians, from the direction of motion) where D = 1.

        cos θ' = b / (1 + sqrt(1 - b²))      [= (1 - 1/γ)/b, without dividing by b]

    ``b``: speed(s) in [0, 1), scalar or array. Returns θ' in (0, π/2]: π/2 at b = 0,
    -> 0 as b -> 1. Inside the ring (smaller θ') light is blueshifted (D > 1).
    """
    s = np.asarray(b, dtype=np.float64)
    if not np.all(np.isfinite(s)) or np.any(s < 0.0) or np.any(s >= 1.0):
        raise ValueError("speed b must be finite and in [0, 1)")
    return _scalar_or_array(np.arccos(s / (1.0 + _inv_gamma(s))))


# --------------------------------------------------------------------------- shutter events


@dataclass(frozen=True, eq=False)
class ShutterEvent:
    """The lab event at which a frame's shutter opens, and the camera's state there.

    ``t``: lab time ct of the event. ``x``: lab position, (3,). ``beta``: camera velocity
    in the lab at the event, (3,); the frame is rendered in the instantaneous comoving
    inertial frame, i.e. boosted by ``lorentz_boost(beta)`` from the lab. ``tau``: the
    camera's proper time ct' at the event (0 at the start of the worldline).
    ``rotation``: the camera's axes at the event, (3, 3) columns right, up, backward (as
    ``PinholeCamera.rotation``), or None for the job's fixed ``[camera]``.
    Arrays are stored as read-only float64 copies. (``eq=False``: events with array
    fields are compared with numpy, not ``==``.)
    """

    t: float
    x: np.ndarray
    beta: np.ndarray
    tau: float
    rotation: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.rotation is not None:
            r = np.array(self.rotation, np.float64).reshape(3, 3)
            r.flags.writeable = False
            object.__setattr__(self, "rotation", r)
        x = _as_vector3(self.x, "x").copy()
        beta = _as_vector3(self.beta, "beta").copy()
        _checked_speed(beta)
        x.flags.writeable = False
        beta.flags.writeable = False
        object.__setattr__(self, "t", float(self.t))
        object.__setattr__(self, "tau", float(self.tau))
        object.__setattr__(self, "x", x)
        object.__setattr__(self, "beta", beta)

    def four_position(self) -> np.ndarray:
        """The lab 4-position (ct, x, y, z) of the event, shape (4,)."""
        return np.concatenate(([self.t], self.x))


def snapshot_event(position: ArrayLike, beta: ArrayLike, ct: float) -> ShutterEvent:
    """Shutter event of a camera moving at constant β since it passed ``position`` at t = τ = 0.

        t = γ ct,   x = position + γ β ct,   τ = ct

    (the seed report's semantics). ``position``: lab position at t = 0, (3,);
    ``beta``: lab velocity, (3,); ``ct``: proper time ct' of the shutter.
    """
    pos = _as_vector3(position, "position")
    v = _as_vector3(beta, "beta")
    g = gamma(v)
    return ShutterEvent(t=g * ct, x=pos + (g * ct) * v, beta=v, tau=ct)


def constant_acceleration_event(
    position: ArrayLike, a_vec: ArrayLike, tau: float, beta0: ArrayLike | None = None
) -> ShutterEvent:
    """Shutter event after proper time τ of constant proper acceleration (hyperbolic motion).

    From rest at ``position`` (t = 0, τ = 0), with a = |a_vec|, â = a_vec/a:

        β = tanh(aτ) â,   t = sinh(aτ)/a,   x = position + (cosh(aτ) - 1)/a â

    With an initial velocity ``beta0`` parallel to â (rapidity φ0 = atanh(β0·â); allowed
    anti-parallel, i.e. braking): β = tanh(φ0 + aτ) â and

        t = [sinh(φ0+aτ) - sinh φ0]/a = τ cosh(φ0 + aτ/2) · sinh(aτ/2)/(aτ/2)
        x - position = [cosh(φ0+aτ) - cosh φ0]/a â = τ sinh(φ0 + aτ/2) · sinh(aτ/2)/(aτ/2) â

    The right-hand forms have no 1/a and no cosh - 1 cancellation, so they stay exact for
    small aτ and a = 0 gives constant velocity (:func:`snapshot_event`).
    ``a_vec``: proper acceleration in lab axes (units 1/length, c = 1), (3,). ``tau``: ct'.
    Raises ValueError if ``beta0`` is not parallel to ``a_vec`` (beyond 1e-12) or if β
    rounds to |β| = 1 in float64 (|φ0 + aτ| above about 19).
    """
    pos = _as_vector3(position, "position")
    acc = _as_vector3(a_vec, "a_vec")
    v0 = np.zeros(3) if beta0 is None else _as_vector3(beta0, "beta0")
    _checked_speed(v0)
    a = float(_hypot3(acc))
    if a == 0.0:
        return snapshot_event(pos, v0, tau)
    a_hat = _unit(acc)
    b0 = float(v0 @ a_hat)
    if float(_hypot3(v0 - b0 * a_hat)) > 1e-12:
        raise ValueError("beta0 must be parallel to the proper acceleration a_vec")
    phi0 = math.atanh(b0)
    half = 0.5 * a * tau
    b = math.tanh(phi0 + 2.0 * half)
    if abs(b) >= 1.0:
        raise ValueError(
            f"rapidity {phi0 + 2.0 * half:.6g} is too large: |beta| rounds to 1 in float64"
        )
    sc = _sinhc(half)
    t = tau * math.cosh(phi0 + half) * sc
    dx = tau * math.sinh(phi0 + half) * sc
    return ShutterEvent(t=t, x=pos + dx * a_hat, beta=b * a_hat, tau=tau)


def integrate_worldline(
    position: ArrayLike,
    beta_of_tau: Callable[[float], ArrayLike],
    tau_end: float,
    steps: int = DEFAULT_RK4_STEPS,
) -> ShutterEvent:
    """Integrate a worldline over proper time with classical RK4 (fixed step).

        dt/dτ = γ(τ),   dx/dτ = γ(τ) β(τ),   t(0) = 0, x(0) = position

    ``beta_of_tau``: lab velocity (3,) as a function of proper time ct'. ``tau_end``: the
    proper time of the returned event (may be negative). ``steps``: number of RK4 steps.
    Because the right-hand side depends on τ only, RK4 is exactly Simpson's rule on each
    step (β is evaluated at the 2·steps + 1 nodes τ_k = k·h/2). Global error
    <= |τ_end| h⁴ max|f''''| / 2880 for each component f of (γ, γβ), h = τ_end/steps;
    a kink in β(τ) (e.g. between keyframes) drops this to O(h²) unless it falls on a node.
    Raises ValueError if any sampled |β| >= 1.
    """
    if int(steps) != steps or steps < 1:
        raise ValueError(f"steps must be a positive integer, got {steps!r}")
    pos = _as_vector3(position, "position")
    n = 2 * int(steps)
    nodes = [tau_end * (k / n) for k in range(n + 1)]
    betas = np.array([_as_vector3(beta_of_tau(s), "beta_of_tau(tau)") for s in nodes])
    g = np.asarray(1.0 / _inv_gamma(_checked_speed(betas)))
    weights = np.full(n + 1, 2.0)
    weights[1::2] = 4.0
    weights[0] = weights[-1] = 1.0
    weights *= tau_end / (3.0 * n)  # h/6 per step, h = 2 τ_end / n
    t = float(weights @ g)
    dx = (weights * g) @ betas
    return ShutterEvent(t=t, x=pos + dx, beta=betas[-1], tau=tau_end)


def _linear_beta_segment(
    beta_a: np.ndarray, beta_b: np.ndarray, dtau: float
) -> tuple[float, np.ndarray]:
    """Exact (Δt, Δx) over a proper-time interval of length ``dtau`` on which β is linear in τ.

    Along the segment β = p_⊥ + u q̂ with q̂ = (β_b - β_a)/w, w = |β_b - β_a|, u running
    linearly from u_a = β_a·q̂ to u_b = u_a + w and p_⊥ fixed. With c = 1/γ and
    R² = 1 - |p_⊥|² = c² + u²:

        Δt = ∫γ dτ  = (dτ/w) [asin(u/R)]_a^b = (dτ/w) · atan2(w K, M)
        Δx = ∫γβ dτ = p_⊥ Δt + q̂ (dτ/w)(c_a - c_b) = p_⊥ Δt + q̂ dτ (u_a + u_b)/(c_a + c_b)

    where atan2(wK, M) is the angle difference written without cancellation:
    M = c_a c_b + u_a u_b and w K = u_b c_a - u_a c_b, K = c_a + u_a (u_a + u_b)/(c_a + c_b)
    (using c_a² - c_b² = u_b² - u_a²). For |wK| << M, atan2(wK, M)/w is evaluated through
    its series, so a constant or slowly varying β is exact and nothing divides by w -> 0.
    """
    c_a = float(_inv_gamma(_hypot3(beta_a)))
    c_b = float(_inv_gamma(_hypot3(beta_b)))
    diff = beta_b - beta_a
    w = float(_hypot3(diff))
    if w == 0.0:
        return dtau / c_a, (dtau / c_a) * beta_a
    q_hat = _unit(diff)
    u_a = float(beta_a @ q_hat)
    u_b = u_a + w
    p_perp = beta_a - u_a * q_hat
    c_sum = c_a + c_b
    K = c_a + u_a * (u_a + u_b) / c_sum
    M = c_a * c_b + u_a * u_b
    z = w * K
    if M > 0.0 and z < 1e-3 * M:
        r2 = (z / M) ** 2  # atan(r)/r = 1 - r²/3 + r⁴/5 - ..., truncation < r⁶/7 < 2e-19
        dt = dtau * K / M * (1.0 - r2 / 3.0 + r2 * r2 / 5.0)
    else:
        dt = dtau * math.atan2(z, M) / w
    dx = dt * p_perp + (dtau * (u_a + u_b) / c_sum) * q_hat
    return dt, dx


def worldline_events(
    position: ArrayLike,
    frames: tuple[int, int],
    ct0: float,
    ct_per_frame: float,
    keyframes: Sequence[tuple[int, ArrayLike]] = (),
    beta_const: ArrayLike | None = None,
    proper_acceleration: ArrayLike | None = None,
) -> list[ShutterEvent]:
    """The shutter event of every frame f = frames[0] .. frames[1] (inclusive).

    Frame f opens its shutter at proper time τ_f = ct0 + (f - frames[0])·ct_per_frame.
    The worldline passes ``position`` (lab) at t = 0, τ = 0. Exactly one motion is used:

    - ``keyframes`` (non-empty; pairs (frame, β) in lab axes): β is linear in frame
      number between keys and held at the first/last key's value outside them. Frame
      and proper time are related by f(τ) = frames[0] + (τ - ct0)/ct_per_frame, so for
      ct_per_frame > 0, β(τ) is piecewise linear in τ with corners at the keys'
      τ_k = ct0 + (f_k - frames[0])·ct_per_frame, and the clamp also covers τ in
      [0, ct0]. The worldline is integrated from τ = 0 **exactly**, segment by
      segment, in closed form (any linear β(τ), collinear or not; see
      ``_linear_beta_segment``), accumulating from frame to frame.
      If ct_per_frame == 0 every frame has τ = ct0 and is a snapshot
      (:func:`snapshot_event`) with the frame's own interpolated β: the frames show
      different cameras, not one accelerating camera.
      Keyframes cannot be combined with ``beta_const`` or ``proper_acceleration``.
    - ``proper_acceleration`` (a lab 3-vector): :func:`constant_acceleration_event` at
      each τ_f, starting from ``beta_const`` (default rest; must be parallel).
    - otherwise constant ``beta_const`` (default 0): :func:`snapshot_event` at each τ_f.

    ``ct_per_frame`` must be >= 0 and ``frames[1] >= frames[0]``. Raises ValueError for
    invalid or conflicting arguments and for any |β| >= 1.
    """
    f0, f1 = (int(f) for f in frames)
    if f1 < f0:
        raise ValueError(f"frames must be (first, last) with last >= first, got {frames!r}")
    if not (math.isfinite(ct0) and math.isfinite(ct_per_frame)) or ct_per_frame < 0.0:
        raise ValueError("ct0 must be finite and ct_per_frame finite and >= 0")
    pos = _as_vector3(position, "position")
    frame_numbers = range(f0, f1 + 1)
    taus = [ct0 + (f - f0) * ct_per_frame for f in frame_numbers]

    if len(keyframes) == 0:
        if proper_acceleration is not None:
            return [
                constant_acceleration_event(pos, proper_acceleration, tau, beta0=beta_const)
                for tau in taus
            ]
        v = np.zeros(3) if beta_const is None else _as_vector3(beta_const, "beta_const")
        return [snapshot_event(pos, v, tau) for tau in taus]

    if beta_const is not None or proper_acceleration is not None:
        raise ValueError("keyframes cannot be combined with beta_const or proper_acceleration")
    keys = sorted((int(f), _as_vector3(v, "keyframe beta")) for f, v in keyframes)
    key_frames = np.array([f for f, _ in keys], dtype=np.float64)
    key_betas = np.array([v for _, v in keys])
    if np.any(np.diff(key_frames) == 0.0):
        raise ValueError("two keyframes share a frame number")
    _checked_speed(key_betas)

    def beta_at_frame(f: float) -> np.ndarray:
        return np.array([np.interp(f, key_frames, key_betas[:, i]) for i in range(3)])

    if ct_per_frame == 0.0:
        return [snapshot_event(pos, beta_at_frame(f), ct0) for f in frame_numbers]

    key_taus = ct0 + (key_frames - f0) * ct_per_frame

    def beta_at_tau(tau: float) -> np.ndarray:
        return beta_at_frame(f0 + (tau - ct0) / ct_per_frame)

    events = []
    tau_cur, beta_cur = 0.0, beta_at_tau(0.0)
    t, dx = 0.0, np.zeros(3)
    for f, tau_f in zip(frame_numbers, taus, strict=True):
        beta_f = beta_at_frame(f)
        lo, hi = min(tau_cur, tau_f), max(tau_cur, tau_f)
        inside = [k for k in range(len(keys)) if lo < key_taus[k] < hi]
        if tau_f < tau_cur:
            inside.reverse()
        nodes = (
            [(tau_cur, beta_cur)]
            + [(float(key_taus[k]), key_betas[k]) for k in inside]
            + [(tau_f, beta_f)]
        )
        for (ta, ba), (tb, bb) in zip(nodes[:-1], nodes[1:], strict=True):
            seg_t, seg_x = _linear_beta_segment(ba, bb, tb - ta)
            t += seg_t
            dx = dx + seg_x
        events.append(ShutterEvent(t=t, x=pos + dx, beta=beta_f, tau=tau_f))
        tau_cur, beta_cur = tau_f, beta_f
    return events


# --------------------------------------------------------------------------- validation


def check_beta(beta: object, key: str = "motion.beta") -> np.ndarray:
    """Validate a user-supplied velocity β (lab axes): 3 finite numbers with |β| < 1.

    Returns a float64 copy, shape (3,). Raises :class:`UserError` naming ``key``, e.g.
    "key 'motion.beta': |beta| = 1.0 must be below 1 (the speed of light)".
    """
    try:
        arr = np.array(beta, dtype=np.float64)
    except (TypeError, ValueError):
        raise UserError(f"beta must be 3 numbers [bx, by, bz], got {beta!r}", key=key) from None
    if arr.shape != (3,):
        raise UserError(f"beta must be 3 numbers [bx, by, bz], got {beta!r}", key=key)
    if not np.all(np.isfinite(arr)):
        raise UserError(f"beta = {arr.tolist()} must be finite", key=key)
    b = float(_hypot3(arr))
    if b >= 1.0:
        raise UserError(f"|beta| = {b!r} must be below 1 (the speed of light)", key=key)
    return arr


# ----------------------------------------------------------------- per-ray kernel form
@njit(nogil=True, error_model="numpy", forceinline=True)
def aberrate_doppler_lane(dx, dy, dz, hx, hy, hz, b, omb, inv_g):
    """:func:`aberrate_doppler_ray` for a caller compiled with reassociation (the SIMD
    lanes, ``render/lane_paths.py``, whose ``fastmath`` allows it; inlined there, so a
    loop of it is vector code, where a call would leave the loop scalar): the same
    forms, with 1 − b given (``omb``, exact in the caller's table) instead of computed,
    so no cancellation depends on the order of an addition (reassociated,
    (1 − b) − |c|²/2 could become 1 − (b + |c|²/2), which loses 1 − cos θ' as b → 1).
    Returns (unit d_lab, D)."""
    cx, cy, cz = dx - hx, dy - hy, dz - hz
    omc = 0.5 * (cx * cx + cy * cy + cz * cz)
    ch = cx * hx + cy * hy + cz * hz
    a = omb - omc
    lx = a * hx + inv_g * (cx - ch * hx)
    ly = a * hy + inv_g * (cy - ch * hy)
    lz = a * hz + inv_g * (cz - ch * hz)
    inv = 1.0 / (omb + b * omc)  # 1 / |l| = 1 / (1 - β·d')
    return lx * inv, ly * inv, lz * inv, inv_g * inv


@njit(cache=True, nogil=True, error_model="numpy")
def aberrate_doppler_ray(dx, dy, dz, hx, hy, hz, b, inv_g):
    """One camera-frame view d' -> (unit d_lab, D), for the kernels (numba, float64).

    The same cancellation-free forms as :func:`aberrate` and :func:`doppler_factor`:
    with the chord c = d' - β̂ (β̂ = (hx, hy, hz), b = |β|, inv_g = 1/γ),
    1 - cos θ' = |c|²/2, d_lab ∝ ((1 - b) - (1 - cos θ')) β̂ + (c - (c·β̂) β̂)/γ and
    D = 1/(γ (1 - β·d')) with 1 - β·d' = (1 - b) + b (1 - cos θ').
    That vector's length is 1 - β·d' itself (with x = cos θ': |c_⊥|² = 1 - x² and
    a = x - b, so a² + (1 - b²)(1 - x²) = (1 - b x)²): one division normalises it and
    gives D, no square root. Call only for b > 0 (at β = 0, d_lab = d' and D = 1
    exactly). (:func:`aberrate_doppler_lane` with 1 − b computed here, without
    reassociation.)
    """
    return aberrate_doppler_lane(dx, dy, dz, hx, hy, hz, b, 1.0 - b, inv_g)


def beta_kernel_args(beta: ArrayLike) -> tuple[float, float, float, float, float]:
    """(β̂x, β̂y, β̂z, b, 1/γ) for :func:`aberrate_doppler_ray`; zeros and 1/γ = 1 at rest."""
    v = _as_vector3(beta, "beta")
    b = float(_checked_speed(v))
    if b == 0.0:
        return 0.0, 0.0, 0.0, 0.0, 1.0
    h = _unit(v)
    return float(h[0]), float(h[1]), float(h[2]), b, float(_inv_gamma(b))
