"""The temperature at which each autopilot evaluates its thermal offset, sample by sample, as
it flies: PX4's 1-s poll and 1 °C publication gate, ArduPilot's low-pass filter.

Both firmwares subtract a cubic ``p(clamp(T))`` (:mod:`calibration.export_firmware`), but
neither evaluates it at every sample's own temperature reading. Read from their public
source:

* **PX4** (``src/modules/temperature_compensation``). ``TemperatureCompensationModule``
  runs once a second (``init``: ``ScheduleOnInterval(1_s)``); ``accelPoll`` takes the
  latest ``sensor_accel`` report and calls ``TemperatureCompensation::update_offsets_accel``
  with its ``temperature``. That computes the offsets at the reading
  (``calc_thermal_offsets_3D``: ``d = clamp(T, TMIN, TMAX) − TREF``, the clamp on the
  reading, not on the gate), but returns "changed" only when ``fabsf(T −
  last_temperature) > 1.0f`` (``last_temperature`` starts at −100 °C, and is reset when the
  parameters change), and only then is ``sensor_correction`` published and
  ``last_temperature`` set to T. ``calibration::Accelerometer::SensorCorrectionsUpdate``
  copies the published offset, and ``Correct`` subtracts it from every sample until the next
  publication. So the offset in use is ``p`` at the reading of the last *publishing* poll.
  A publication triggered by another sensor's gate (``TC_G_ENABLE`` gyro, ``TC_B_ENABLE``
  baro: same ``sensor_correction`` message) would carry the accel offset of the latest
  poll; the files ``soakcal export`` writes set ``TC_A_ENABLE`` only, and that is what is
  simulated here (a gyro on the same die has the same reading and gates at the same polls).
* **ArduPilot** (``libraries/AP_InertialSensor``). ``AP_InertialSensor_Backend::
  _rotate_and_correct_accel`` calls ``TCal::correct_accel`` with
  ``_imu.get_temperature(instance)``: the temperature the backend last published. The
  InvenSense drivers (``AP_InertialSensor_Invensense``: MPU-6000/9250, ICM-2060x/20689)
  pass every FIFO sample's temperature through ``_temp_filter``, a ``LowPassFilter2pFloat``
  built with (1000 Hz, 1 Hz): a 2-pole Butterworth biquad (``DigitalBiquadFilter::
  compute_params``, bilinear with pre-warping), and publish the filtered value in
  ``update()``. Other backends differ: ``AP_InertialSensor_Invensensev3`` (ICM-42xxx)
  default-constructs its ``temp_filter`` (zero cut-off: ``apply`` returns the sample
  unfiltered), ``AP_InertialSensor_BMI088`` publishes the raw register reading every
  101st FIFO read, unfiltered. Only the InvenSense 1-Hz filter is simulated here; the
  unfiltered backends are the per-sample application.

What is not simulated: the phase of PX4's poll against the log (the first poll is at the
log's first sample), the few milliseconds between a poll and the sensors module's use of
the new offset, ArduPilot's publication latency (one main-loop period) and its driver rate
(the filter runs at the log's own sample rate: the same 1-Hz response for any rate well
above 1 Hz), and float32 evaluation of the polynomial (the gate's comparison is in float32).
"""

from __future__ import annotations

import math

import numpy as np

PX4_POLL_PERIOD_S = 1.0  # TemperatureCompensationModule::init, ScheduleOnInterval(1_s)
PX4_UPDATE_GATE_C = 1.0  # update_offsets_accel: fabsf(T - last_temperature) > 1.0f
PX4_FIRST_LAST_C = -100.0  # PerSensorData: last_temperature = -100.0f (first poll publishes)
ARDUPILOT_TEMP_CUTOFF_HZ = 1.0  # AP_InertialSensor_Invensense: _temp_filter(1000, 1)


def px4_reading_in_use(t_s: np.ndarray, temp_c: np.ndarray, *,
                       poll_period_s: float = PX4_POLL_PERIOD_S,
                       gate_c: float = PX4_UPDATE_GATE_C) -> np.ndarray:
    """(N,) °C: the reading at which the PX4 offset subtracted from each sample was computed.

    Polls at ``t_s[0] + k·poll_period_s``, each taking the latest sample's reading; a poll
    whose reading differs from the last published one by more than ``gate_c`` (float32,
    strictly) publishes it, and every later sample uses it until the next publication.
    The clamp to TMIN/TMAX belongs to the polynomial (evaluate ``p(clamp(·))`` at the
    returned readings)."""
    t = np.asarray(t_s, float)
    temp = np.asarray(temp_c, float)
    if t.size == 0:
        return temp.copy()
    n_polls = int(math.floor((t[-1] - t[0]) / poll_period_s)) + 1
    polls = np.searchsorted(t, t[0] + poll_period_s * np.arange(n_polls), side="right") - 1
    reading32 = temp.astype(np.float32)
    gate32 = np.float32(gate_c)
    last = np.float32(PX4_FIRST_LAST_C)
    starts, values = [], []
    for i in polls:
        r = reading32[i]
        if np.abs(r - last) > gate32:
            last = r
            starts.append(int(i))
            values.append(float(temp[i]))
    out = np.empty_like(temp)
    bounds = [*starts, temp.size]
    for k, v in enumerate(values):
        out[bounds[k]:bounds[k + 1]] = v
    return out


def butterworth2_coefficients(sample_hz: float, cutoff_hz: float
                              ) -> tuple[np.ndarray, np.ndarray]:
    """(b, a) of the 2-pole Butterworth low-pass ArduPilot's ``DigitalBiquadFilter``
    computes: ω = tan(π·f_c/f_s), c = 1 + √2·ω + ω², b = (ω², 2ω², ω²)/c,
    a = (1, 2(ω² − 1)/c, (1 − √2·ω + ω²)/c)."""
    w = math.tan(math.pi * cutoff_hz / sample_hz)
    c = 1.0 + math.sqrt(2.0) * w + w * w
    b0 = w * w / c
    return (np.array([b0, 2.0 * b0, b0]),
            np.array([1.0, 2.0 * (w * w - 1.0) / c, (1.0 - math.sqrt(2.0) * w + w * w) / c]))


def ardupilot_reading_in_use(t_s: np.ndarray, temp_c: np.ndarray, *,
                             cutoff_hz: float = ARDUPILOT_TEMP_CUTOFF_HZ) -> np.ndarray:
    """(N,) °C: the temperature ArduPilot's InvenSense backends hand to ``correct_accel`` at
    each sample: the reading through the 2-pole 1-Hz low-pass (:func:`butterworth2_coefficients`)
    at the log's own sample rate (median interval), started settled at the first reading
    (the vehicle powered before the log)."""
    from scipy.signal import lfilter, lfilter_zi

    t = np.asarray(t_s, float)
    temp = np.asarray(temp_c, float)
    if temp.size < 2:
        return temp.copy()
    sample_hz = 1.0 / float(np.median(np.diff(t)))
    b, a = butterworth2_coefficients(sample_hz, cutoff_hz)
    out, _ = lfilter(b, a, temp, zi=lfilter_zi(b, a) * temp[0])
    return out


def ardupilot_filter_delay_s(cutoff_hz: float = ARDUPILOT_TEMP_CUTOFF_HZ) -> float:
    """The 2-pole Butterworth low-pass's delay for a slow ramp (its group delay at 0 Hz):
    √2 / (2π·f_c), 0.225 s at 1 Hz; a reading changing at r °C/s is followed r × that
    behind."""
    return math.sqrt(2.0) / (2.0 * math.pi * cutoff_hz)


# ArduPilot's accelerometer device ids (INS_ACC_ID, INS_ACC2_ID, INS_ACC3_ID) carry the
# driver's DevTypes value (AP_InertialSensor_Backend.h) in bits 16-23 (AP_HAL::Device's
# bus id: bus type, bus, address, devtype). The types AP_InertialSensor_Invensense
# registers (its start(): the MPU-6000/6500 and ICM-20608 share 0x13), whose temperature
# goes through the 1-Hz filter above; and the types of drivers that publish it unfiltered
# (AP_InertialSensor_Invensensev3's default-constructed temp_filter; BMI088's raw
# register reading). Other types: not read here, so not known.
ARDUPILOT_FILTERED_DEVTYPES = {0x13: "MPU-6000/6500 or ICM-20608", 0x16: "MPU-9250",
                               0x27: "ICM-20789", 0x28: "ICM-20689", 0x2F: "ICM-20602",
                               0x30: "ICM-20601"}
ARDUPILOT_UNFILTERED_DEVTYPES = {0x2B: "BMI088", 0x33: "ICM-40609", 0x34: "ICM-42688",
                                 0x35: "ICM-42605", 0x36: "ICM-40605", 0x37: "IIM-42652",
                                 0x3A: "ICM-42670"}


def ardupilot_accel_reading(accel_id: int) -> tuple[str | None, str]:
    """(the temperature reading the accelerometer's driver hands ``INS_TCAL``: "filtered",
    "per-sample" or None when not known, and a description of the device) for an
    ArduPilot accelerometer device id (``INS_ACCn_ID``)."""
    devtype = (int(accel_id) >> 16) & 0xFF
    if devtype in ARDUPILOT_FILTERED_DEVTYPES:
        return "filtered", (f"an {ARDUPILOT_FILTERED_DEVTYPES[devtype]} "
                            f"(AP_InertialSensor_Invensense: its temperature through a 2-pole "
                            f"{ARDUPILOT_TEMP_CUTOFF_HZ:g}-Hz low-pass)")
    if devtype in ARDUPILOT_UNFILTERED_DEVTYPES:
        chip = ARDUPILOT_UNFILTERED_DEVTYPES[devtype]
        driver = "BMI088" if chip == "BMI088" else "Invensensev3"
        article = "an" if chip[0] in "AEIOU" else "a"
        return "per-sample", (f"{article} {chip} (AP_InertialSensor_{driver}: its "
                              f"temperature unfiltered)")
    return None, f"device type 0x{devtype:02X}"
