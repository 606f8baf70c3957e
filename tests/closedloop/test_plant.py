"""The closed-loop plant: friction, the actuator's latency and lag, slide against delay."""

from __future__ import annotations

import math

import numpy as np
import pytest

from slipkit.closedloop.plant import (
    G_M_S2,
    Actuator,
    GraspPlant,
    slip_distance_driven,
)
from slipkit.errors import SlipkitError
from slipkit.families.tactip.physics import slip_indentation_mm


def _plant(**kw):  # type: ignore[no-untyped-def]
    args = {
        "mass_kg": 0.1,
        "mu_s": 1.0,
        "mu_k": 0.5,
        "stiffness": 0.5,
        "indentation_mm": 3.0,
        "arm_mm_s": 0.0,
        "actuator": Actuator(0.0, 0.0),
        "rate_hz": 120.0,
        "substeps": 8,
    }
    args.update(kw)
    return GraspPlant(**args)


def test_friction_holds_when_grip_force_is_enough() -> None:
    """A grip with mu_s F_n above the weight never lets the object move."""
    plant = _plant()
    for _ in range(240):
        state = plant.step()
    assert (0.0, False, True) == (
        state.drop_mm,
        state.sliding,
        math.isnan(state.onset_s),
    )


def test_object_slides_when_grip_force_is_too_small() -> None:
    """Below the holding indentation the object slides with a = g (1 - mu_k F_n / (m g))."""
    depth = 0.5 * slip_indentation_mm(0.1 * G_M_S2, 1.0, 0.5)
    plant = _plant(indentation_mm=depth)
    force = plant.force(depth)
    accel = G_M_S2 * (1.0 - 0.5 * force / (0.1 * G_M_S2)) * 1e3  # mm/s^2
    for _ in range(12):  # 0.1 s
        state = plant.step()
    # semi-implicit Euler: v_n = a n h, x_n = a h^2 n (n + 1) / 2 with h = 1/960 s
    h, n = 1.0 / 960.0, 96
    expected = accel * h * h * n * (n + 1) / 2.0
    assert expected == pytest.approx(state.drop_mm, rel=1e-9)


def test_actuator_latency_then_first_order_lag() -> None:
    """A step command shows nothing during the latency, then 1 - 1/e of the step one tau later."""
    act = Actuator(0.02, 0.01)
    act.command(0.0, 100.0)
    h = 1e-4
    seen = [act.advance(i * h, h) for i in range(300)]  # seen[i]: output at (i + 1) h
    at_latency = seen[round(0.02 / h) - 1]
    at_tau = seen[round(0.03 / h) - 1]
    assert (0.0, pytest.approx(100.0 * (1 - math.exp(-1)), rel=1e-3)) == (
        at_latency,
        at_tau,
    )


@pytest.mark.parametrize(
    ("speed", "delay_frames", "latency", "retract"),
    [(50.0, 1, 0.024, 1.0), (20.0, 3, 0.01, 10.0), (100.0, 0, 0.05, 0.1)],
)
def test_slip_distance_at_constant_speed_matches_closed_form(
    speed: float, delay_frames: int, latency: float, retract: float
) -> None:
    """Slide = v (delay + latency) (1 + v_retract / v_catch) for a driven object and an instant arm."""
    catch = 100.0
    mass, mu_s, k = 0.1, 1.0, 0.5
    d_slip = slip_indentation_mm(mass * G_M_S2, mu_s, k)
    rate, sub = 120.0, 200
    act = Actuator(latency, 0.0, initial=-retract)
    plant = GraspPlant(
        mass_kg=mass,
        mu_s=mu_s,
        mu_k=0.5,
        stiffness=k,
        indentation_mm=d_slip + retract * 0.02,  # onset 20 ms in
        arm_mm_s=-retract,
        actuator=act,
        driven_speed_mm_s=speed,
        rate_hz=rate,
        substeps=sub,
        travel_mm=1e6,
    )
    commanded = math.nan
    seen = 0
    while math.isnan(plant.state.arrest_s) and plant.state.t < 2.0:
        s = plant.state
        if not math.isnan(s.onset_s) and math.isnan(commanded):
            if seen == delay_frames:
                commanded = s.t
                act.command(s.t, catch)
            seen += 1
        plant.step()
    delay = commanded - plant.state.onset_s
    expected = slip_distance_driven(
        speed_mm_s=speed,
        delay_s=delay,
        latency_s=latency,
        retract_mm_s=retract,
        catch_mm_s=catch,
    )
    # Onset and arrest are each located within one substep (1 / 24000 s).
    assert expected == pytest.approx(
        plant.state.drop_mm, abs=2.5 * speed / (rate * sub)
    )


def test_plant_refuses_kinetic_above_static_friction() -> None:
    """mu_k > mu_s is refused, naming the field."""
    with pytest.raises(SlipkitError, match="mu_k"):
        _plant(mu_k=1.5)


def test_plant_force_is_the_scene_hertz_law() -> None:
    """The plant's grip force equals slipkit.families.tactip.physics.normal_force_N (the scene's law)."""
    from slipkit.families.tactip.physics import normal_force_N

    plant = _plant()
    depths = [0.0, 0.3, 1.7, 3.0, 5.0]
    expected = [float(normal_force_N(np.asarray(d), 0.5)) for d in depths]
    assert expected == pytest.approx([plant.force(d) for d in depths], rel=1e-12)
