"""The simulated rig end to end, and the physics on its own (integrate-on-read)."""

from __future__ import annotations

import numpy as np
import pytest

from drivers import adxl355
from drivers.clock import VirtualClock
from drivers.geometry import angles_for_reference, reference_for_angles
from drivers.protocols import Accelerometer, Chamber, Turntable
from simulators.chamber_sim import ChamberPhysics
from simulators.cli import build_parser, run_sim
from simulators.rig import RigFaults, connect_rig, start_sim_rig
from simulators.truth import SensorTruth
from simulators.turntable_sim import TurntablePhysics


def test_chamber_physics_integrates_on_read_only() -> None:
    clock = VirtualClock()
    p = ChamberPhysics(clock, np.random.default_rng(0), ramp_c_per_min=1.0, running=True,
                       setpoint_c=-40.0, die_tau_s=900.0)
    clock.advance(3600.0)
    assert p.t_s == 0.0 and p.air_c == 23.0  # nothing happens until someone looks
    p.advance_to()
    assert p.t_s == 3600.0
    assert p.working_setpoint_c == pytest.approx(23.0 - 60.0)
    assert p.setpoint_c < p.air_c < p.die_c  # air lags the ramp, die lags the air
    clock.advance(6 * 3600.0)
    p.advance_to()
    assert p.air_c == pytest.approx(-40.0, abs=1e-6)
    assert p.die_c == pytest.approx(-40.0, abs=0.01)


def test_chamber_cannot_exceed_its_own_rate() -> None:
    clock = VirtualClock()
    p = ChamberPhysics(clock, np.random.default_rng(0), ramp_c_per_min=0.0, running=True,
                       setpoint_c=80.0, max_rate_c_per_min=5.0)
    clock.advance(60.0)
    p.advance_to()
    assert p.air_c == pytest.approx(28.0)  # 5 °C/min cap, not the 60 s first-order step


async def test_the_served_sensor_reads_its_die_history_hysteresis_and_rate() -> None:
    """A twin carrying hysteresis and rate sensitivity (``twin fit`` writes them) served on
    the bridge: z reads +h after a heating and −h after a cooling at the same die
    temperature, and k·dT/dt while the die moves. Before, the served bridge read every
    capture as a die at rest that never moved (only the offline simulator had them)."""
    from simulators.bridge_sim import BridgeDevice
    from simulators.effects import TemperatureRate, ThermalHysteresis

    h_z, k_z = 2e-3, 0.05  # g; g per °C/s (0.83 mg per °C/min)
    truth = SensorTruth.adxl355_typical(3)
    truth.effects = [ThermalHysteresis(h_g=np.array([0.0, 0.0, h_z])),
                     TemperatureRate(k_g_per_c_per_s=np.array([0.0, 0.0, k_z]))]
    clock = VirtualClock()
    p = ChamberPhysics(clock, np.random.default_rng(0), air_c=20.0, setpoint_c=20.0,
                       running=True, ramp_c_per_min=0.0, die_tau_s=300.0)

    dev = BridgeDevice(truth, clock, np.random.default_rng(1), p.die_now_c, lambda: (0.0, 0.0),
                       die_motion=p.die_motion_now)

    async def z_offset_g() -> float:  # the capture's mean less the base model at its die
        counts, _ = await dev.capture(4000)
        mean_g = adxl355.counts_to_g(counts, truth.range_g).mean(axis=0)
        return float(mean_g[2] - truth.ideal_raw_g(dev.reference_g()[None, :], p.die_c)[0, 2])

    assert abs(await z_offset_g()) < 1e-4  # never moved, at rest
    p.setpoint_c = 40.0
    clock.advance(300.0)
    offset = await z_offset_g()
    assert p.die_direction == 1 and p.die_rate_c_per_s > 0.01
    assert offset == pytest.approx(h_z + k_z * p.die_rate_c_per_s, abs=1e-4)
    clock.advance(6 * 3600.0)  # settled at 40 °C: +h after the heating
    assert await z_offset_g() == pytest.approx(h_z, abs=1e-4)
    p.setpoint_c = 20.0
    clock.advance(6 * 3600.0)  # back at 20 °C after a cooling: −h
    assert await z_offset_g() == pytest.approx(-h_z, abs=1e-4)


def test_table_profile_is_trapezoidal() -> None:
    clock = VirtualClock()
    t = TurntablePhysics(clock, slew_deg_per_s=10.0, accel_deg_per_s2=10.0, settle_s=1.0)
    t.move_to((100.0, 0.5, 0.0))
    clock.advance(1.0)
    assert t.true_angles_deg()[0] == pytest.approx(5.0)  # ½ a t²
    clock.advance(10.0)  # 100° at 10 °/s with 1 s ramps: 11 s
    assert t.true_angles_deg()[0] == pytest.approx(100.0)
    assert not t.moving() and not t.in_position()
    clock.advance(1.0)
    assert t.in_position()


async def test_rig_end_to_end_matches_truth() -> None:
    clock = VirtualClock()
    truth = SensorTruth.adxl355_typical(5)
    async with start_sim_rig(clock, seed=5, truth=truth, chamber_map="watlow_f4t",
                             die_tau_s=600.0) as rig:
        chamber, table, sensor = await connect_rig(rig, clock)
        assert isinstance(chamber, Chamber) and isinstance(table, Turntable)
        assert isinstance(sensor, Accelerometer)
        assert rig.sensor_url.startswith("socket://127.0.0.1:")
        await sensor.configure(2.0, 62.5)
        await chamber.set_ramp_rate(3.0)
        await chamber.set_setpoint(-10.0)
        await chamber.run()
        ref = np.array([0.0, -1.0, 1.0]) / np.sqrt(2.0)
        angles = angles_for_reference(ref)
        await table.move_to(angles)
        while not (await table.read_status()).in_position:
            await clock.sleep(1.0)
        await clock.sleep(3 * 3600.0)
        status = await chamber.read_status()
        assert status.process_c == pytest.approx(-10.0, abs=0.1)
        acq = await sensor.acquire(400)
        die_c = rig.chamber.die_c
        assert die_c == pytest.approx(-10.0, abs=0.05)
        expected = truth.ideal_raw_g(reference_for_angles(angles), die_c)[0]
        # 400 samples of ~35 µg rms each: the mean is good to a few µg.
        np.testing.assert_allclose(acq.mean_g, expected, atol=2e-5)
        assert acq.sensor_c == pytest.approx(die_c + truth.temp_offset_c, abs=0.1)
        await sensor.close()


async def test_rig_die_lags_air() -> None:
    clock = VirtualClock()
    async with start_sim_rig(clock, seed=1, die_tau_s=900.0) as rig:
        chamber, _, sensor = await connect_rig(rig, clock)
        # A step (the twin's ramp register 0; the driver refuses 0 on a map that does not
        # say 0 means "no ramp").
        await chamber.link.write_field(chamber.regmap.ramp_c_per_min, 0.0)
        await chamber.set_setpoint(43.0)
        await chamber.run()
        await clock.sleep(900.0)  # air is at 43 °C after ~5 min at 5 °C/min
        acq = await sensor.acquire(50)
        air = (await chamber.read_status()).process_c
        assert air == pytest.approx(43.0, abs=0.2)
        die = acq.sensor_c - rig.bridge.truth.temp_offset_c
        assert 30.0 < die < 40.0  # one tau of lag behind a 20 °C step, less the ramp-up
        await sensor.close()


async def test_rig_faults_switch_at_run_time() -> None:
    clock = VirtualClock()
    faults = RigFaults()
    async with start_sim_rig(clock, seed=1, faults=faults) as rig:
        _, table, sensor = await connect_rig(rig, clock)
        faults.table.never_in_position = True
        await table.move_to((5.0, 0.0, 0.0))
        await clock.sleep(30.0)
        assert not (await table.read_status()).in_position
        faults.table.never_in_position = False
        assert (await table.read_status()).in_position
        await sensor.close()


def test_cli_parser_and_short_run(capsys: pytest.CaptureFixture[str]) -> None:
    args = build_parser().parse_args(["--chamber-map", "watlow_f4t", "--p-drop", "0.1"])
    assert args.chamber_map == "watlow_f4t" and args.p_drop == 0.1
    assert run_sim(["--duration-s", "0.2"]) == 0
    out = capsys.readouterr().out
    assert "tcp://127.0.0.1:" in out and "socket://127.0.0.1:" in out
    assert "eurotherm3216" in out


async def test_benchmark_campaign_smoke() -> None:
    """The bench's campaign loop, shrunk: every step reached, every row plausible."""
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parents[2] / "benchmarks" / "bench_twin.py"
    spec = importlib.util.spec_from_file_location("bench_twin", path)
    assert spec is not None and spec.loader is not None
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    STEPS_C, run_campaign = bench.STEPS_C, bench.run_campaign

    res = await run_campaign(n_positions=2, n_samples=20, soak_s=60.0, in_memory=True)
    assert res["rows"] == 2 * len(STEPS_C)
    assert res["worst_norm_err_g"] < 0.1  # |a| ≈ 1 g up to the sensor's own errors
    # 163 °C of ramping at 2 °C/min (23 → −40 → 60) is 81.5 min before any settling.
    assert res["sim_hours"] > 81.5 / 60.0
