"""Per-position quality checks."""

from __future__ import annotations

from drivers.protocols import Acquisition
from service.engine.quality import QualityLimits, check_acquisition, noise_span_c

LIM = QualityLimits(expected_sd_g=2.5e-4, temp_noise_c=0.0)  # span read from a clean channel


def acq(**kw) -> Acquisition:  # type: ignore[no-untyped-def]
    base = dict(mean_g=(0.0, 0.0, 1.0), sd_g=(2.4e-4, 2.6e-4, 2.5e-4), n=200, sensor_c=20.0,
                sensor_c_span=0.05, saturated=False, duration_s=3.2)
    base.update(kw)
    return Acquisition(**base)  # type: ignore[arg-type]


def test_good_capture_passes() -> None:
    assert check_acquisition(acq(), 200, LIM) == []


def test_each_check_names_itself() -> None:
    assert check_acquisition(acq(n=199), 200, LIM) == ["sample_count"]
    assert check_acquisition(acq(sd_g=(2e-3, 2e-4, 2e-4)), 200, LIM) == ["noise_sd"]
    assert check_acquisition(acq(sensor_c_span=0.25), 200, LIM) == ["temperature_span"]
    assert check_acquisition(acq(saturated=True), 200, LIM) == ["saturated"]
    assert check_acquisition(acq(n=10, saturated=True), 200, LIM) == ["sample_count", "saturated"]


def test_temperature_span_allows_the_noise_range_of_a_raw_channel() -> None:
    noisy = QualityLimits(temp_noise_c=0.1)
    allowance_c = noise_span_c(200, 0.1)
    assert 0.6 < allowance_c < 0.9  # ~2σ√(2 ln n) + σ for n = 200
    assert check_acquisition(acq(sensor_c_span=allowance_c + 0.1), 200, noisy) == []
    assert check_acquisition(acq(sensor_c_span=allowance_c + 0.25), 200, noisy) == [
        "temperature_span"]
