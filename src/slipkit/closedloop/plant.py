"""The reduced grasp plant: an object held by friction, a gripper actuator with latency and lag.

One object of mass ``m`` is pressed by a fingertip with normal force ``F_n`` and pulled
along the contact by a tangential load ``Q`` (its weight ``m g`` in the TacTip gravity
drop). Coulomb friction decides (Johnson, *Contact Mechanics*, 1985, Sec. 7.1):

* **stuck** while ``Q <= mu_s F_n``: the object does not move;
* **sliding** otherwise: ``m dv/dt = Q - mu_k F_n`` (gravity-driven), or at an imposed
  constant speed (``driven_speed_mm_s``: a conveyor or a pulled object, used by the
  closed-form tests); it re-sticks when its speed reaches zero while
  ``Q <= mu_s F_n`` (driven: as soon as ``Q <= mu_s F_n``).

The fingertip is moved by an arm: the controller commands the arm's velocity (mm/s,
positive presses in), the :class:`Actuator` delivers it after a pure latency and a
first-order lag, the indentation ``delta`` integrates the arm velocity and the normal
force follows the Hertz law ``F_n = K delta^1.5`` (:func:`slipkit.families.tactip.physics.normal_force_N`,
the law the TacTip scene uses). The plant is stepped once per sensor frame and
integrated inside the frame with ``substeps`` semi-implicit Euler steps, so the onset
and the arrest fall within a frame, not on frame boundaries.

Written by hand (no ODE library): the plant is a handful of scalar states stepped in
lock-step with a detector that must see one frame at a time, which a
``scipy.integrate`` solver's own step control does not allow; the tests check the
integration against the closed forms (:func:`slip_distance_driven`).
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Callable, Collection, Mapping
from dataclasses import dataclass, field
from typing import Any

from slipkit._options import Rule, check_value, within
from slipkit.errors import SlipkitError

G_M_S2 = 9.81  # gravitational acceleration, m/s^2

# Declared ranges of the parameters every family's plant shares (the configs'
# comments say the same): wide enough for any gripper or hand, narrow enough that a
# typo cannot ask for hours of simulation or terabytes of frames.
#: actuator dead time, s: a trial simulates about a second after the slip
LATENCY_S = within(0.0, 0.5, "s")
#: actuator first-order lag, s
LAG_S = within(0.0, 0.5, "s")
#: one phase of a trial (approach, press, lift, hold, after), s
PHASE_S = within(0.0, 10.0, "s")
#: plant integration steps per sensor frame
SUBSTEPS = within(1, 64, whole_number=True)
#: object mass, kg (a value or a [lo, hi] drawn per trial)
MASS_KG = within(0.0, 20.0, "kg", above=True, span=True)
#: static and kinetic friction coefficients (silicone skins reach about 3)
MU_S = within(0.0, 5.0, above=True, span=True)
MU_K = within(0.0, 5.0, span=True)
#: grip force limit of a hand or gripper, N
FORCE_N = within(0.0, 500.0, "N", above=True)
#: slide that loses the object, mm
TRAVEL_MM = within(0.0, 5000.0, "mm", above=True)


def check_params(
    params: Mapping[str, Any],
    rules: Mapping[str, Rule],
    where: str = "closedloop.plant",
    *,
    optional: Collection[str] = (),
) -> None:
    """Refuse the first parameter outside its declared range, naming it.

    ``closedloop.plant.hold_s=1e9: expected a number in [0, 10] s`` (a
    :class:`~slipkit.errors.SlipkitError`); ``params`` is a plain mapping. A key in
    ``optional`` may be left out (the code has a default for it).
    """
    for key, rule in rules.items():
        if key in optional and key not in params:
            continue
        check_value(f"{where}.{key}", params.get(key), rule)


def span(value: Any) -> tuple[float, float]:
    """``(lo, hi)`` of a parameter given as a number or as ``[lo, hi]`` (drawn per trial)."""
    items = list(value) if isinstance(value, list | tuple) else [value, value]
    return float(items[0]), float(items[-1])


#: a grid of conditions: ``n`` values log-spaced from ``lo`` to ``hi``
GRID_N = within(1, 100, whole_number=True)


def check_grid(
    node: Mapping[str, Any], where: str, value: Rule, *, n: Rule = GRID_N
) -> tuple[float, float, int]:
    """``(lo, hi, n)`` of a conditions grid ``{lo, hi, n}`` at ``where``, each in range, ``lo <= hi``."""
    check_params(node, {"lo": value, "hi": value, "n": n}, where)
    lo, hi = float(node["lo"]), float(node["hi"])
    if lo > hi:
        raise SlipkitError(f"{where}.lo={lo:g}: expected <= {where}.hi ({hi:g})")
    return lo, hi, int(node["n"])


def _check(
    name: str, value: float, *, minimum: float = 0.0, strict: bool = False
) -> float:
    value = float(value)
    ok = math.isfinite(value) and (value > minimum if strict else value >= minimum)
    if not ok:
        sign = ">" if strict else ">="
        raise SlipkitError(
            f"{name}: must be a finite number {sign} {minimum}; got {value!r}"
        )
    return value


@dataclass
class Actuator:
    """A velocity command delivered after a pure latency and a first-order lag.

    Parameters
    ----------
    latency_s : float
        Dead time between a command and the actuator starting to follow it, s.
    tau_s : float
        Time constant of the first-order lag, s (0: follows at once).
    initial : float
        Output (and standing command) at the start, in the command's unit (mm/s).

    Attributes
    ----------
    output : float
        The delivered value now (mm/s).
    """

    latency_s: float
    tau_s: float
    initial: float = 0.0
    output: float = field(init=False)
    _commands: list[tuple[float, float]] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        self.latency_s = _check("latency_s", self.latency_s)
        self.tau_s = _check("tau_s", self.tau_s)
        self.output = float(self.initial)
        self._commands = [(-math.inf, float(self.initial))]

    def command(self, t: float, value: float) -> None:
        """Issue ``value`` at time ``t`` (s); it takes effect at ``t + latency_s``."""
        self._commands.append((float(t) + self.latency_s, float(value)))

    def target(self, t: float) -> float:
        """The command in effect at time ``t`` (the latest one issued at or before ``t - latency``)."""
        value = self._commands[0][1]
        for when, v in self._commands:
            if when <= t + 1e-12:
                value = v
            else:
                break
        return value

    def advance(self, t: float, h: float) -> float:
        """Move the output from ``t`` over ``h`` s towards the command in effect at ``t``; return it.

        The command is held over the step (zero-order hold), so the lag's response is
        exact at the step ends: ``y(t0 + n h) = u + (y0 - u) exp(-n h / tau)``.
        """
        goal = self.target(t)
        if self.tau_s == 0.0:
            self.output = goal
        else:
            self.output += (goal - self.output) * -math.expm1(-h / self.tau_s)
        return self.output


@dataclass
class PlantState:
    """What the plant knows at one instant (the oracle reads ``sliding``).

    Attributes
    ----------
    t : float
        Time, s.
    indentation_mm : float
        Fingertip indentation ``delta``, mm (0: no contact).
    arm_mm_s : float
        Arm velocity, mm/s (positive presses in).
    normal_N : float
        Normal (grip) force, N.
    drop_mm : float
        Distance the object has slid since the start, mm.
    speed_mm_s : float
        Object slip speed, mm/s.
    sliding : bool
        Whether the object is sliding now.
    onset_s : float
        First slip onset, s (NaN until it slips).
    arrest_s : float
        When the slip stopped (re-stick after an onset), s (NaN until then);
        :class:`PinchPlant` moves it to the latest re-stick.
    dropped : bool
        The object slid past the plant's travel: it is lost.
    slide_start_s : float
        Start of the current (or latest) slide, s (NaN until it slips).
    load_N : float
        Tangential load on the contact now, N (NaN where the plant does not track it).
    tangential_N : float
        Tangential force one contact transmits now, N: its share of the load while
        stuck, kinetic friction while sliding (NaN where the plant does not track it).
    normal_rate_N_s : float
        Change of the grip force over the last frame, N/s (NaN where not tracked).
    """

    t: float
    indentation_mm: float
    arm_mm_s: float
    normal_N: float
    drop_mm: float = 0.0
    speed_mm_s: float = 0.0
    sliding: bool = False
    onset_s: float = math.nan
    arrest_s: float = math.nan
    dropped: bool = False
    slide_start_s: float = math.nan
    load_N: float = math.nan
    tangential_N: float = math.nan
    normal_rate_N_s: float = math.nan


class SteppedPlant(ABC):
    """What every plant shares: a frame (``1 / rate_hz`` s) advanced in ``substeps``
    steps of :meth:`_substep` (a subclass's dynamics) until the object drops, and the
    re-stick that ends a slide (:meth:`_stick`: the first arrest after the onset is
    kept)."""

    state: PlantState
    rate_hz: float
    substeps: int

    @abstractmethod
    def _substep(self, h: float) -> None:
        """Advance the plant's dynamics by ``h`` s."""

    def _stick(self, t: float) -> None:
        s = self.state
        s.sliding = False
        s.speed_mm_s = 0.0
        if not math.isnan(s.onset_s) and math.isnan(s.arrest_s):
            s.arrest_s = t

    def step(self) -> PlantState:
        """Advance one frame (``1 / rate_hz`` s, in ``substeps`` steps); the new state."""
        h = 1.0 / self.rate_hz / self.substeps
        for _ in range(self.substeps):
            if self.state.dropped:
                self.state.t += h
                continue
            self._substep(h)
        return self.state


class GraspPlant(SteppedPlant):
    """A fingertip pressing an object that friction holds against a tangential load.

    Parameters
    ----------
    mass_kg : float
        Object mass, kg.
    mu_s, mu_k : float
        Static and kinetic friction coefficients (``0 <= mu_k <= mu_s``).
    stiffness : float
        Hertz ``K`` in ``F_n = K delta^1.5``, N/mm^1.5.
    indentation_mm : float
        Indentation at the start, mm.
    arm_mm_s : float
        Arm velocity at the start, mm/s (negative: retracting).
    actuator : Actuator
        Delivers the commanded arm velocity (its ``initial`` should be ``arm_mm_s``).
    load_N : float, optional
        Tangential load, N; default the weight ``m g``.
    travel_mm : float
        Slide past which the object is lost (dropped), mm.
    max_indentation_mm : float
        The arm stops pressing at this indentation (a position limit), mm.
    driven_speed_mm_s : float, optional
        Slide at this constant speed instead of accelerating under the load.
    rate_hz : float
        Frame rate the plant is stepped at, Hz.
    substeps : int
        Integration steps per frame.
    """

    def __init__(
        self,
        *,
        mass_kg: float,
        mu_s: float,
        mu_k: float,
        stiffness: float,
        indentation_mm: float,
        arm_mm_s: float,
        actuator: Actuator,
        load_N: float | None = None,
        travel_mm: float = 50.0,
        max_indentation_mm: float = math.inf,
        driven_speed_mm_s: float | None = None,
        rate_hz: float = 120.0,
        substeps: int = 8,
    ) -> None:
        self.mass_kg = _check("mass_kg", mass_kg, strict=True)
        self.mu_s = _check("mu_s", mu_s, strict=True)
        self.mu_k = _check("mu_k", mu_k)
        if self.mu_k > self.mu_s:
            raise SlipkitError(
                f"mu_k: need 0 <= mu_k <= mu_s ({self.mu_s}); got {mu_k!r}"
            )
        self.stiffness = _check("stiffness", stiffness, strict=True)
        self.load_N = (
            self.mass_kg * G_M_S2 if load_N is None else _check("load_N", load_N)
        )
        self.travel_mm = _check("travel_mm", travel_mm, strict=True)
        self.max_indentation_mm = float(max_indentation_mm)
        self.driven = (
            None
            if driven_speed_mm_s is None
            else _check("driven_speed_mm_s", driven_speed_mm_s, strict=True)
        )
        self.rate_hz = _check("rate_hz", rate_hz, strict=True)
        if int(substeps) != substeps or substeps < 1:
            raise SlipkitError(
                f"substeps: must be a whole number >= 1; got {substeps!r}"
            )
        self.substeps = int(substeps)
        self.actuator = actuator
        depth = _check("indentation_mm", indentation_mm)
        self.state = PlantState(
            t=0.0,
            indentation_mm=depth,
            arm_mm_s=float(arm_mm_s),
            normal_N=self.force(depth),
        )
        self._settle()

    def force(self, indentation_mm: float) -> float:
        """Normal force at an indentation, N (Hertz, ``K delta^1.5``).

        The scalar form of :func:`slipkit.families.tactip.physics.normal_force_N` (the numpy
        call costs more than the arithmetic on one float; a test checks they agree).
        """
        return self.stiffness * max(indentation_mm, 0.0) ** 1.5

    def holds(self, normal_N: float) -> bool:
        """Whether static friction carries the load at this normal force."""
        return self.load_N <= self.mu_s * normal_N

    def _settle(self) -> None:
        """At the start an object the grip cannot hold is already sliding."""
        s = self.state
        if not self.holds(s.normal_N):
            s.sliding = True
            s.onset_s = s.t
            s.slide_start_s = s.t

    def _substep(self, h: float) -> None:
        s = self.state
        t_next = s.t + h
        v = self.actuator.advance(s.t, h)
        depth = s.indentation_mm + v * h
        if depth >= self.max_indentation_mm and v > 0:
            depth = self.max_indentation_mm
        s.indentation_mm = max(depth, 0.0)
        s.arm_mm_s = v
        s.normal_N = self.force(s.indentation_mm)
        if not s.sliding and not self.holds(s.normal_N):
            s.sliding = True
            s.slide_start_s = t_next
            if math.isnan(s.onset_s):
                s.onset_s = t_next
        if s.sliding:
            if self.driven is not None:
                if self.holds(s.normal_N):
                    self._stick(t_next)
                else:
                    s.speed_mm_s = self.driven
            else:
                # m a = Q - mu_k F_n (N / kg = m/s^2 -> x 1e3 for mm/s^2), semi-implicit.
                accel = 1e3 * (self.load_N - self.mu_k * s.normal_N) / self.mass_kg
                speed = s.speed_mm_s + accel * h
                if speed <= 0.0 and self.holds(s.normal_N):
                    self._stick(t_next)
                else:
                    s.speed_mm_s = max(speed, 0.0)
            s.drop_mm += s.speed_mm_s * h
            if s.drop_mm > self.travel_mm:
                s.dropped = True
        s.t = t_next


class PinchPlant(SteppedPlant):
    """An object pinched by a force-controlled hand under a tangential load that changes in time.

    A prosthetic or robot hand holds the object between ``contacts`` fingertips with grip
    force ``F_n`` (N, the normal force on each contact, what an FSR or a BioTac reads);
    the controller commands ``F_n`` through an :class:`Actuator` (latency and first-order
    lag, the command in N), clipped to ``[0, max_force_N]``. The tangential load ``Q(t)``
    (N: the weight once lifted, plus a load increase) is given as a function of time.
    Coulomb friction over the contacts (Johnson 1985, Sec. 7.1): stuck while
    ``Q <= contacts mu_s F_n``; sliding ``m dv/dt = Q - contacts mu_k F_n``; re-stuck
    when the speed returns to zero with ``Q <= contacts mu_s F_n``. It can slip again
    later (the load keeps rising): ``onset_s`` stays the first onset, ``arrest_s``
    moves to the latest re-stick, ``slide_start_s`` marks each slide's start.

    Parameters
    ----------
    mass_kg : float
        Object mass, kg.
    mu_s, mu_k : float
        Static and kinetic friction coefficients (``0 <= mu_k <= mu_s``).
    contacts : int
        Fingertips sharing the load (2: a pinch).
    load : callable
        ``Q(t)``, N, for ``t`` in s.
    actuator : Actuator
        Delivers the commanded grip force, N.
    max_force_N : float
        Grip force limit of the hand, N.
    travel_mm : float
        Slide past which the object leaves the grasp (dropped), mm.
    rate_hz : float
        Frame rate the plant is stepped at, Hz.
    substeps : int
        Integration steps per frame.
    """

    def __init__(
        self,
        *,
        mass_kg: float,
        mu_s: float,
        mu_k: float,
        contacts: int,
        load: Callable[[float], float],
        actuator: Actuator,
        max_force_N: float,
        travel_mm: float,
        rate_hz: float,
        substeps: int = 1,
    ) -> None:
        self.mass_kg = _check("mass_kg", mass_kg, strict=True)
        self.mu_s = _check("mu_s", mu_s, strict=True)
        self.mu_k = _check("mu_k", mu_k)
        if self.mu_k > self.mu_s:
            raise SlipkitError(
                f"mu_k: need 0 <= mu_k <= mu_s ({self.mu_s}); got {mu_k!r}"
            )
        if int(contacts) != contacts or contacts < 1:
            raise SlipkitError(
                f"contacts: must be a whole number >= 1; got {contacts!r}"
            )
        self.contacts = int(contacts)
        self.load = load
        self.actuator = actuator
        self.max_force_N = _check("max_force_N", max_force_N, strict=True)
        self.travel_mm = _check("travel_mm", travel_mm, strict=True)
        self.rate_hz = _check("rate_hz", rate_hz, strict=True)
        if int(substeps) != substeps or substeps < 1:
            raise SlipkitError(
                f"substeps: must be a whole number >= 1; got {substeps!r}"
            )
        self.substeps = int(substeps)
        force = min(max(actuator.output, 0.0), self.max_force_N)
        self.state = PlantState(
            t=0.0,
            indentation_mm=math.nan,
            arm_mm_s=math.nan,
            normal_N=force,
            load_N=float(load(0.0)),
            tangential_N=float(load(0.0)) / self.contacts,
            normal_rate_N_s=0.0,
        )

    def holds(self, normal_N: float, load_N: float) -> bool:
        """Whether static friction over the contacts carries ``load_N`` at this grip."""
        return load_N <= self.contacts * self.mu_s * normal_N

    def _substep(self, h: float) -> None:
        s = self.state
        t_next = s.t + h
        s.normal_N = min(max(self.actuator.advance(s.t, h), 0.0), self.max_force_N)
        s.load_N = q = float(self.load(t_next))
        if not s.sliding and not self.holds(s.normal_N, q):
            s.sliding = True
            s.slide_start_s = t_next
            if math.isnan(s.onset_s):
                s.onset_s = t_next
        if s.sliding:
            # m a = Q - n mu_k F_n (N / kg = m/s^2 -> x 1e3 for mm/s^2), semi-implicit.
            accel = 1e3 * (q - self.contacts * self.mu_k * s.normal_N) / self.mass_kg
            speed = s.speed_mm_s + accel * h
            if speed <= 0.0 and self.holds(s.normal_N, q):
                s.sliding = False
                s.speed_mm_s = 0.0
                s.arrest_s = t_next
            else:
                s.speed_mm_s = max(speed, 0.0)
            s.drop_mm += s.speed_mm_s * h
            if s.drop_mm > self.travel_mm:
                s.dropped = True
        s.tangential_N = self.mu_k * s.normal_N if s.sliding else q / self.contacts
        s.t = t_next

    def step(self) -> PlantState:
        """Advance one frame (:meth:`SteppedPlant.step`); the new state, with the grip's
        rate of change over the frame."""
        before = self.state.normal_N
        state = super().step()
        state.normal_rate_N_s = (state.normal_N - before) * self.rate_hz
        return state


def slip_distance_driven(
    *,
    speed_mm_s: float,
    delay_s: float,
    latency_s: float,
    retract_mm_s: float,
    catch_mm_s: float,
) -> float:
    """Slide (mm) of an object driven at a constant speed, with an arm that reverses at once.

    The object starts sliding at the onset, when the retracting arm's indentation
    falls through the holding indentation; the detector declares ``delay_s`` later,
    the actuator starts ``latency_s`` after that (with no lag), so the arm retracts
    ``retract_mm_s (delay + latency)`` too far and then presses back at
    ``catch_mm_s``; friction holds again when the indentation is back where it
    slipped. Slide = ``v (delay + latency) (1 + v_retract / v_catch)``.
    """
    dead = delay_s + latency_s
    return speed_mm_s * dead * (1.0 + retract_mm_s / catch_mm_s)
