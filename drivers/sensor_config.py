"""The sensor entry of a rig config → a typed link config, with errors naming the key.

A rig config's ``sensors[0]`` (docs/sensor-bridge.md, "Rig config keys")::

    {"url": "/dev/ttyACM0", "baudrate": 115200,
     "protocol": "bridge",            # "bridge" (framed commands) or "stream" (plain lines)
     "framing": "v2",                 # bridge only: "v2" (CRC-16) or "v1" (XOR, old bridges)
     "stream": {"units": "g", "columns": ["x", "y", "z", "t"], "range_g": 2},
     "serial_binding": "auto",        # "auto", "eeprom", "table" or "any"
     "serials": {"E6614104035F2B2F": "SN-0001"}}   # board uid → sensor serial

A multiplexing bridge (docs/sensor-bridge.md, "Channels") declares the sensor on each
of its channels: ``"channels": {"0": "SN-1", "1": "SN-2"}`` (its ``serials`` table is then
keyed ``"<board uid>@<channel>"``).

Only parsing lives here (the rig config loader calls it); the drivers take the
result. :func:`make_accelerometer` builds the matching driver.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Literal

from drivers.bridge_protocol import FRAMINGS, MAX_CHANNEL, Framing
from drivers.clock import Clock
from drivers.protocols import Accelerometer

LinkProtocol = Literal["bridge", "stream"]
BindingMode = Literal["auto", "eeprom", "table", "any"]
StreamUnits = Literal["g", "mg", "m/s2"]

PROTOCOLS: tuple[LinkProtocol, ...] = ("bridge", "stream")
BINDING_MODES: tuple[BindingMode, ...] = ("auto", "eeprom", "table", "any")
STREAM_UNITS: tuple[StreamUnits, ...] = ("g", "mg", "m/s2")
STREAM_COLUMNS = ("x", "y", "z", "t")


@dataclass(frozen=True)
class StreamFormat:
    """How a plain streaming line is read: column order, acceleration units, range."""

    units: StreamUnits = "g"
    columns: tuple[str, ...] = STREAM_COLUMNS  # a permutation of x, y, z, t
    range_g: float = 2.0  # full scale the firmware was set to: |a| ≥ range_g flags saturation


@dataclass(frozen=True)
class SensorLinkConfig:
    url: str
    baudrate: int = 115200
    protocol: LinkProtocol = "bridge"
    framing: Framing = "v2"
    stream: StreamFormat = field(default_factory=StreamFormat)
    serial_binding: BindingMode = "auto"
    serials: dict[str, str] = field(default_factory=dict)  # board uid → serial
    # A multiplexing bridge: channel → the serial of the sensor on it; empty: one sensor.
    channels: dict[int, str] = field(default_factory=dict)


class SensorConfigError(ValueError):
    """A sensor config the drivers cannot use; the message names the key."""


def sensor_config_errors(cfg: Any, path: str = "sensors[0]") -> list[tuple[str, str]]:
    """``(key path, problem)`` for every problem of one sensor entry; empty when usable."""
    if not isinstance(cfg, dict):
        return [(path, "expected an object with at least a url")]
    errors: list[tuple[str, str]] = []
    if not isinstance(cfg.get("url"), str) or not cfg["url"]:
        errors.append((f"{path}.url", "expected the sensor's serial port or URL"))
    baud = cfg.get("baudrate", 115200)
    if not isinstance(baud, int) or isinstance(baud, bool) or baud <= 0:
        errors.append((f"{path}.baudrate", "expected a positive integer (bit/s)"))
    protocol = cfg.get("protocol", "bridge")
    if protocol not in PROTOCOLS:
        errors.append((f"{path}.protocol", f"expected one of {', '.join(PROTOCOLS)}, "
                                           f"got {protocol!r}"))
    if cfg.get("framing", "v2") not in FRAMINGS:
        errors.append((f"{path}.framing", f"expected one of {', '.join(FRAMINGS)}, "
                                          f"got {cfg.get('framing')!r}"))
    errors += _stream_errors(cfg.get("stream", {}), f"{path}.stream")
    mode = cfg.get("serial_binding", "auto")
    if mode not in BINDING_MODES:
        errors.append((f"{path}.serial_binding", f"expected one of {', '.join(BINDING_MODES)}, "
                                                 f"got {mode!r}"))
    serials = cfg.get("serials", {})
    if not isinstance(serials, dict) or not all(
            isinstance(k, str) and k and isinstance(v, str) and v.strip()
            for k, v in serials.items()):
        errors.append((f"{path}.serials", "expected an object {board uid: sensor serial} "
                                          "of non-empty strings"))
    elif mode == "table" and not serials:
        errors.append((f"{path}.serials", "serial_binding 'table' needs at least one "
                                          "board uid → serial entry"))
    if protocol == "stream" and mode in ("eeprom", "table"):
        errors.append((f"{path}.serial_binding", "a plain stream reports no identity: "
                                                 "use 'any' (the operator's word)"))
    if "channels" in cfg:
        errors += _channel_errors(cfg, path)
    return errors


def _channel_errors(cfg: dict[str, Any], path: str) -> list[tuple[str, str]]:
    """A multiplexing bridge's ``channels``: ``{"<ch>": serial}``, each serial once."""
    channels = cfg["channels"]
    if not isinstance(channels, dict) or not channels:
        return [(f"{path}.channels", "expected an object {channel: sensor serial} with at "
                                     "least one channel, e.g. {\"0\": \"SN-1\", \"1\": \"SN-2\"}")]
    errors: list[tuple[str, str]] = []
    seen: dict[str, str] = {}
    for key, serial in channels.items():
        where = f"{path}.channels.{key}"
        if not (isinstance(key, str) and key.isdigit() and key.isascii()
                and str(int(key)) == key and int(key) <= MAX_CHANNEL):
            errors.append((where, f"expected a channel number 0..{MAX_CHANNEL} as the key"))
        elif not isinstance(serial, str) or not serial.strip():
            errors.append((where, "expected the serial of the sensor on this channel"))
        elif serial.strip() in seen:
            errors.append((where, f"sensor {serial.strip()!r} is already on channel "
                                  f"{seen[serial.strip()]}"))
        else:
            seen[serial.strip()] = key
    if cfg.get("protocol", "bridge") != "bridge":
        errors.append((f"{path}.channels", "only a framed bridge has channels (a plain stream "
                                           "carries no address)"))
    if cfg.get("framing", "v2") != "v2":
        errors.append((f"{path}.channels", "a multiplexing bridge speaks v2 framing (v1 is "
                                           "for bridges flashed before channels existed)"))
    if "serial" in cfg:
        errors.append((f"{path}.serial", "a multiplexing bridge names its sensors in "
                                         "'channels', not 'serial'"))
    table = cfg.get("serials")
    if isinstance(table, dict):
        off = sorted({str(v).strip() for v in table.values()} - set(seen))
        if off:
            errors.append((f"{path}.serials", f"{', '.join(off)} is on no channel of this "
                                              f"bridge (keys are '<board uid>@<channel>')"))
    return errors


def _stream_errors(stream: Any, path: str) -> list[tuple[str, str]]:
    if not isinstance(stream, dict):
        return [(path, "expected an object {units, columns, range_g}")]
    errors: list[tuple[str, str]] = []
    if stream.get("units", "g") not in STREAM_UNITS:
        errors.append((f"{path}.units", f"expected one of {', '.join(STREAM_UNITS)}, "
                                        f"got {stream.get('units')!r}"))
    columns = stream.get("columns", list(STREAM_COLUMNS))
    if not isinstance(columns, list) or sorted(columns) != sorted(STREAM_COLUMNS):
        errors.append((f"{path}.columns", "expected the four names x, y, z, t in the order "
                                          "the firmware prints them"))
    rng = stream.get("range_g", 2.0)
    if not isinstance(rng, int | float) or isinstance(rng, bool) or not rng > 0:
        errors.append((f"{path}.range_g", "expected the full scale in g (> 0)"))
    return errors


def parse_sensor_config(cfg: Any, path: str = "sensors[0]") -> SensorLinkConfig:
    """Typed config; :class:`SensorConfigError` naming the first bad key."""
    problems = sensor_config_errors(cfg, path)
    if problems:
        key, why = problems[0]
        raise SensorConfigError(f"{key}: {why}")
    stream = cfg.get("stream", {})
    return SensorLinkConfig(
        url=cfg["url"], baudrate=int(cfg.get("baudrate", 115200)),
        protocol=cfg.get("protocol", "bridge"), framing=cfg.get("framing", "v2"),
        stream=StreamFormat(units=stream.get("units", "g"),
                            columns=tuple(stream.get("columns", STREAM_COLUMNS)),
                            range_g=float(stream.get("range_g", 2.0))),
        serial_binding=cfg.get("serial_binding", "auto"),
        serials={k: v.strip() for k, v in cfg.get("serials", {}).items()},
        channels={int(k): v.strip() for k, v in cfg.get("channels", {}).items()},
    )


def make_accelerometer(link: SensorLinkConfig, clock: Clock) -> Accelerometer:
    """The driver a link config means: framed bridge or plain stream (unaddressed: a
    multiplexing bridge's channels come from :func:`make_multiplexed_bridge`)."""
    if link.protocol == "stream":
        from drivers.stream_sensor import StreamingAccelerometer

        return StreamingAccelerometer(link.url, clock, fmt=link.stream, baudrate=link.baudrate)
    from drivers.sensor_bridge import SerialAccelerometer

    return SerialAccelerometer(link.url, clock, baudrate=link.baudrate, framing=link.framing)


def make_multiplexed_bridge(link: SensorLinkConfig, clock: Clock) -> Any:
    """The :class:`drivers.sensor_bridge.MultiplexedBridge` of a link with ``channels``."""
    from drivers.sensor_bridge import MultiplexedBridge

    return MultiplexedBridge(link.url, clock, baudrate=link.baudrate, framing=link.framing)
