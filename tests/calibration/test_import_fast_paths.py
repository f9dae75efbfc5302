"""The C-speed paths of ``soakcal import`` and the recording reader/writer agree with the
per-cell paths they stand in for (issue 20, "Speed").

Each test runs both paths explicitly (the fast one switched off by replacing it) and
compares the results bit for bit, or the error message, including the line number.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np
import pytest

from calibration import importers, importers_plain, importers_table, recording
from calibration.errors import RecordingError
from calibration.importers_cli import run_import
from calibration.importers_table import TableUnits, _leading_banner
from tests.calibration.test_recording_plain import _assert_same

UNITS = TableUnits(accel="g")


def _read(path: Path, monkeypatch: pytest.MonkeyPatch | None = None, **kw: object) -> tuple:
    """read_table with the fast path (None) or with it switched off (monkeypatch); returns
    (outcome, whether the fast path answered)."""
    answered: list[bool] = []
    real = importers_plain.parse_plain_rows

    def spy(*args: object, **kwargs: object) -> np.ndarray | None:
        out = real(*args, **kwargs) if monkeypatch is None else None
        answered.append(out is not None)
        return out

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(importers_table, "parse_plain_rows", spy)
        try:
            raw = importers_table.read_table(path, **{"units": UNITS, **kw})
        except RecordingError as exc:
            return ("error", str(exc)), any(answered)
    arrays = tuple(None if a is None else a.tobytes()  # bit for bit: -0.0 and NaN too
                   for a in (raw.t_s, raw.acc_g, raw.temp_c))
    return ("ok", arrays, raw.notes), any(answered)


def _both(path: Path, **kw: object) -> tuple[tuple, bool]:
    fast, answered = _read(path, **kw)
    slow, _ = _read(path, pytest.MonkeyPatch(), **kw)
    assert fast == slow
    return fast, answered


AWKWARD = ["-0.0", "1e-5", "1E+3", ".5", "5.", "+3", " 1.5 ", "\t2\t", "007",
           "0.1000000000000000055511151231257827021181583404541015625",
           "9007199254740993", "2.2250738585072011e-308", "4.9e-324",
           "1.7976931348623157e308", "-1.0000000000000002", "123456789012345678901234567890"]


def _table(path: Path, rows: list[list[str]], header: str = "t_s,ax,ay,az,temp_c,label",
           delim: str = ",", tail: str = "\n") -> Path:
    lines = ([header] if header else []) + [delim.join(r) for r in rows]
    path.write_text("\n".join(lines) + tail, encoding="utf-8")
    return path


def _rows(n: int, rng: np.random.Generator) -> list[list[str]]:
    return [[f"{0.01 * i:.4f}", repr(float(rng.normal(0, 0.01))), f"{rng.normal(0, 0.01):.9e}",
             f"{1 + rng.normal(0, 0.01):+.12f}", f"{25 + 0.0078 * (i // 7):.4f}",
             f"tag#{i % 3} x"] for i in range(n)]


def test_awkward_numbers_take_the_fast_path_and_match(tmp_path):
    rng = np.random.default_rng(5)
    rows = _rows(60, rng)
    for k, cell in enumerate(AWKWARD):  # each awkward number in a value column (ax, ay)
        rows[k][1 + k % 2] = cell
    rows[20][3] = " 1e0"
    out, answered = _both(_table(tmp_path / "a.csv", rows))
    assert out[0] == "ok" and answered  # the fast path took it, and agreed
    for delim, name in ((";", "s.csv"), ("\t", "t.csv")):
        text_rows = [[c.strip() for c in r] for r in rows]
        header = delim.join(["t_s", "ax", "ay", "az", "temp_c", "label"])
        out, answered = _both(_table(tmp_path / name, text_rows, header=header, delim=delim,
                                     tail="\n\n\n"))
        assert out[0] == "ok" and answered


def test_banner_and_no_header_take_the_fast_path_and_match(tmp_path):
    rows = [[f"{25 - 0.01 * i:.3f}", "0.25", "0.003", "-0.03"] for i in range(30)]
    path = _table(tmp_path / "p.csv", rows, header="")
    path.write_text("=~= PuTTY log =~=\n0.1,0.2\n" + path.read_text())
    kw = dict(columns="ax=2,ay=3,az=4,temp=1",
              units=TableUnits(accel="counts", counts_per_g=0.25, rate_hz=50.0))
    out, answered = _both(path, **kw)
    assert out[0] == "ok" and answered
    assert any("2 leading line(s) skipped" in n for n in out[2])


@pytest.mark.parametrize("cell,line_error", [
    ("nan", True), ("inf", True), ("1e999", True), ("2_5", False), (" ", False),
    ("x", True), ('"1.5"', False), ("\u0661", False), ("1 2", True), ("\x0c1", False),
])
def test_what_the_fast_path_declines_is_read_or_refused_by_the_per_cell_reader(
        tmp_path, cell, line_error):
    rows = _rows(20, np.random.default_rng(6))
    rows[7][4] = cell  # the temperature column: an empty cell is "not recorded" there
    out, answered = _both(_table(tmp_path / "d.csv", rows))
    assert not answered
    assert (out[0] == "error") == line_error
    if line_error:
        assert "d.csv:9:" in out[1] and "temp_c" in out[1]


def test_empty_temperature_cells_take_the_fast_path_and_match(tmp_path):
    """A temperature logged at a tenth of the acceleration's rate: its other cells empty."""
    rows = _rows(200, np.random.default_rng(13))
    for i, row in enumerate(rows):
        if i % 10:
            row[4] = ""
    rows[0][0], rows[5][5] = "0", ""  # an empty text cell too (not read)
    out, answered = _both(_table(tmp_path / "e.csv", rows))
    assert answered and out[0] == "ok"
    temp = np.frombuffer(out[1][2], float)
    assert np.isnan(temp).sum() == 180 and np.isfinite(temp[::10]).all()
    # the last column: a trailing empty cell
    last = [[r[0], r[1], r[2], r[3], r[5], r[4]] for r in rows]
    out, answered = _both(_table(tmp_path / "f.csv", last, header="t_s,ax,ay,az,label,temp_c"))
    assert answered and out[0] == "ok"


@pytest.mark.parametrize("where", ["ax", "label with n"])
def test_empty_cells_the_fast_path_leaves_to_the_per_cell_reader(tmp_path, where):
    rows = _rows(50, np.random.default_rng(14))
    for row in rows[::3]:
        row[4] = ""
    if where == "ax":
        rows[31][1] = ""  # an empty acceleration cell: refused, naming its line
    else:
        rows[2][5] = "nan"  # a letter n in the text: its own "nan" could not be told apart
    out, answered = _both(_table(tmp_path / "g.csv", rows))
    assert not answered
    if where == "ax":
        assert out[0] == "error" and "g.csv:33:" in out[1] and "'ax'" in out[1]
    else:
        assert out[0] == "ok"


@pytest.mark.parametrize("edit", ["blank line", "short row", "long row", "non-ascii label",
                                  "cr", "one row"])
def test_table_edits_agree(tmp_path, edit):
    rows = _rows(15, np.random.default_rng(7))
    header = "t_s,ax,ay,az,temp_c,label"
    if edit == "short row":
        rows[4] = rows[4][:-1]
    elif edit == "long row":
        rows[9].append("5")
    elif edit == "non-ascii label":
        rows[3][5] = "°C"
    elif edit == "one row":
        rows = rows[:1]
    path = _table(tmp_path / "e.csv", rows, header=header)
    if edit == "blank line":
        path.write_text(path.read_text().replace("\n", "\n\n", 3))
    elif edit == "cr":
        path.write_bytes(path.read_bytes().replace(b"\n", b"\r\n"))
    out, answered = _both(path)
    if edit == "short row":
        assert out == ("error", f"{path}:6: has 5 cells, header has 6 (a garbled line of a "
                                "serial log? --bad-lines skip leaves such lines out, each "
                                "named)") and not answered
    if edit == "long row":
        assert out[0] == "error" and f"{path}:11:" in out[1]
    if edit in ("cr", "one row"):
        assert answered and out[0] == "ok"


def test_the_command_writes_the_same_recording_and_summary_either_way(tmp_path, capsys):
    rng = np.random.default_rng(8)
    rows = _rows(3000, rng)
    for k, cell in enumerate(c for c in AWKWARD if abs(float(c)) < 2):  # within ±8 g
        rows[100 + k][1] = cell.strip()
    src = _table(tmp_path / "log.csv", rows)
    results = []
    for fast in (True, False):
        out = tmp_path / f"rec_{fast}.csv"
        args = argparse.Namespace(format="csv", raw=str(src), output=str(out),
                                  raw_samples=False, min_static_s=None, threshold=None,
                                  window_s=None, trim_s=None, accel_unit="g")
        with pytest.MonkeyPatch.context() as mp:
            if not fast:
                mp.setattr(importers_table, "parse_plain_rows", lambda *a, **k: None)
            assert run_import(args) == 0
        results.append((out.read_bytes(), capsys.readouterr().out.replace(str(out), "OUT")))
    assert results[0] == results[1]
    assert b"-0.0," in results[0][0]  # the awkward numbers reached the recording


# --- the writer -------------------------------------------------------------------
def _special_floats() -> np.ndarray:
    vals = [0.0, -0.0, 1e-5, 1e-4, 9.999e-5, 1e16, 1e15, 9999999999999998.0, 1e22, 0.1,
            1 / 3, 5e-324, 2.2250738585072014e-308, 1.7976931348623157e308, 2.0**53,
            2.0**63, -(2.0**63), 1e20, 123.0, -7.0, 2.5, math.nan, math.inf, -math.inf]
    return np.array(vals)


def _columns(n: int, rng: np.random.Generator) -> dict[str, np.ndarray]:
    bits = rng.integers(np.iinfo(np.int64).min, np.iinfo(np.int64).max, n, dtype=np.int64)
    wild = bits.view(np.float64)  # every exponent, subnormals, NaNs and infinities
    special = np.resize(_special_floats(), n)
    whole = np.resize(np.r_[_special_floats(), np.arange(20.0)], n)
    return {"t_s": np.arange(n) / 1000.0, "step": whole, "position": np.full(n, 3.0),
            "n": rng.integers(1, 10**6, n), "visit": rng.integers(0, 2, n).astype(bool),
            "ax": wild, "ay": special, "az": rng.normal(1, 1e-3, n).astype(np.float32),
            "sensor_c": np.full(n, math.nan), "sd_x": rng.integers(-5, 5, n)}


@pytest.mark.parametrize("chunk_rows", [7, 1 << 16])
def test_the_column_writer_writes_what_the_row_writer_writes(monkeypatch, chunk_rows):
    monkeypatch.setattr(recording, "WRITE_CHUNK_ROWS", chunk_rows)
    cols = _columns(200_000 if chunk_rows > 7 else 500, np.random.default_rng(9))
    header = list(cols)
    chunks = recording._csv_chunks(header, [cols[h] for h in header])
    assert chunks is not None
    want = recording._csv_text(header, zip(*(cols[h] for h in header), strict=True))
    assert "".join(chunks) == want


def test_write_recording_file_is_the_row_writers_text(tmp_path):
    n = 1000
    rng = np.random.default_rng(10)
    cols = {"t_s": np.cumsum(rng.uniform(0, 1, n)), "sensor_c": rng.uniform(-40, 85, n),
            "ax": rng.normal(0, 1e-3, n), "ay": -rng.normal(0, 1e-3, n),
            "az": 1 + rng.normal(0, 1e-3, n), "n": np.ones(n)}
    rec = recording.Recording.from_columns(cols)
    recording.write_recording(tmp_path / "r.csv", rec)
    rows = zip(*(rec.columns[h] for h in rec.header), strict=True)
    assert (tmp_path / "r.csv").read_text() == recording._csv_text(rec.header, rows)
    assert recording.recording_text(rec) == (tmp_path / "r.csv").read_text()


def test_columns_the_column_writer_does_not_take_go_row_by_row():
    assert recording._csv_chunks(["a", "b"], [np.zeros(2), [0.0, 1.0]]) is None
    assert recording._csv_chunks(["a", "b"], [np.zeros(2), np.zeros(3)]) is None
    assert recording._csv_chunks(["a", "b"], [np.zeros(2), np.zeros(2, np.longdouble)]) is None
    assert recording._csv_chunks(["a"], [np.zeros(2)]) is None  # one cell a row: csv quotes ""


# --- the reader of recordings, all-numeric header ----------------------------------------
NUMERIC_HEADER = "t_s,step,chamber_c,position,ref_x,ref_y,ref_z,ax,ay,az,n,sd_x,sd_y,sd_z"


@pytest.mark.parametrize("seed", range(40))
def test_numeric_recording_is_read_or_refused_as_the_row_reader_does(seed):
    rng = np.random.default_rng(100 + seed)
    n = int(rng.integers(1, 30))
    rows = [[repr(i * 15.2), str(i // 8), f"{rng.uniform(-40, 60):.3f}", str(i % 8), "0.0",
             "0.0", "1.0", repr(float(rng.normal(0, 0.6))), f"{rng.normal():.9e}",
             f"{rng.normal():+.12f}", "200", f"{abs(rng.normal(1e-4, 1e-5)):.6g}", "0.0001",
             ".0001"] for i in range(n)]
    damage = ["", " ", "nan", "inf", "1_0", "1e5", "+.5", "-0", "1.", "9" * 70, "9" * 64,
              "1e-400", "1e400", "0x10", "-", ".", "1e", "+-1", "1.2.3", "e5", "E", "--1"]
    for _ in range(int(rng.integers(0, 4))):
        i, j = int(rng.integers(n)), int(rng.integers(len(rows[0])))
        rows[i][j] = str(rng.choice(damage))
    text = "\n".join([NUMERIC_HEADER] + [",".join(r) for r in rows]) + "\n"
    edit = int(rng.integers(5))
    if edit == 1:
        lines = text.split("\n")
        lines.insert(int(rng.integers(1, len(lines) + 1)), "")
        text = "\n".join(lines)
    elif edit == 2:
        text += ",,,,,,,,,,,,,\n"  # an all-empty row
    elif edit == 3:
        text = text.replace(",", ",,", 1)
    elif edit == 4:
        text = text.rstrip("\n") + "\n\n\n"
    _assert_same(text)


def test_numeric_recording_takes_the_block_checks(monkeypatch):
    rng = np.random.default_rng(11)
    text = recording.recording_text(recording.Recording.from_columns({
        "t_s": np.arange(300.0), "chamber_c": np.full(300, 20.0),
        "ax": rng.normal(0, 0.1, 300), "ay": np.zeros(300), "az": np.ones(300),
        "sd_x": np.full(300, math.nan)}))
    calls: list[object] = []
    real = recording._numeric_cells
    monkeypatch.setattr(recording, "_numeric_cells",
                        lambda *a: calls.append(real(*a)) or calls[-1])
    rec = recording._parse_plain(text, "r.csv")
    assert rec is not None and calls == [True]  # the block checks saw the empty sd_x cells
    assert np.isnan(rec.columns["sd_x"]).all()
    _assert_same(text)


# --- the rest of the import ---------------------------------------------------------
def _moving_variance_before(acc: np.ndarray, window_n: int) -> np.ndarray:
    """The whole-array formula moving_variance had before issue 20."""
    x = np.asarray(acc, float) - np.asarray(acc, float)[0]
    n = x.shape[0]
    half = max(int(window_n) // 2, 1)
    c1 = np.vstack([np.zeros((1, 3)), np.cumsum(x, axis=0)])
    c2 = np.vstack([np.zeros((1, 3)), np.cumsum(x * x, axis=0)])
    idx = np.arange(n)
    lo = np.clip(idx - half, 0, n)
    hi = np.clip(idx + half + 1, 0, n)
    cnt = (hi - lo)[:, None].astype(float)
    mean = (c1[hi] - c1[lo]) / cnt
    var = (c2[hi] - c2[lo]) / cnt - mean**2
    return np.clip(var, 0.0, None)


@pytest.mark.parametrize("n,window", [(5000, 100), (7, 3), (50, 200), (3, 1), (1, 3),
                                      (10, 9), (11, 9), (12, 9)])
def test_moving_variance_is_the_same_numbers(n, window):
    """Slices in the interior, indices at the ends (every split of n against the window)."""
    rng = np.random.default_rng(n)
    acc = np.array([0.3, -0.2, 9.8]) + rng.normal(0, 1e-3, (n, 3)) + np.linspace(0, 1, n)[:, None]
    before = _moving_variance_before(acc, window)
    assert importers.moving_variance(acc, window).tobytes() == before.tobytes()
    norm = importers.moving_variance_norm(acc, window)
    assert norm.tobytes() == np.linalg.norm(before, axis=1).tobytes()


@pytest.mark.parametrize("text", [
    "banner\n" + "\n" * 40 + "a,b\n1,2\n3,4\n5,6\n",
    "\n".join(f"line {i}" for i in range(30)) + "\nt,x\n1,2\n",
    "a,b\n1,2\n",
    "x\x0cy\n" * 30 + "a,b\n" + "1,2\n" * 5,
    "",
])
def test_the_leading_lines_are_enough_for_the_banner_search(text):
    head, lines = importers_plain.head_lines(text, 20, 3)
    full = text.splitlines()
    assert lines == full[:len(lines)] and text.startswith(head)
    assert _leading_banner(lines, None) == _leading_banner(full, None)


# --- DataFlash: the IMU messages at once against DFReader's message loop -------------------
def _old_style_dataflash(path: Path, n: int, *, temp_format: str = "f") -> Path:
    """IMU and IMU2 without an ``I`` field (logs before ArduPilot 4.0), ``T`` as
    ``temp_format`` (``c``: centi-degrees, DFReader divides by 100)."""
    import struct

    from tests.calibration.log_writers import DF_HEAD, FMT_ID, PARM_ID, _df_fmt

    fmt = "QffffffII" + temp_format + "BBHH"
    cols = "TimeUS,GyrX,GyrY,GyrZ,AccX,AccY,AccZ,EG,EA,T,GH,AH,GHz,AHz"
    body = "<" + fmt.replace("c", "h")
    length = 3 + struct.calcsize(body)
    out = bytearray(_df_fmt(FMT_ID, "FMT", "BBnNZ", "Type,Length,Name,Format,Columns", 89))
    out += _df_fmt(130, "IMU", fmt, cols, length) + _df_fmt(132, "IMU2", fmt, cols, length)
    out += _df_fmt(PARM_ID, "PARM", "QNf", "TimeUS,Name,Value", 3 + struct.calcsize("<Q16sf"))
    out += DF_HEAD + struct.pack("<BQ16sf", PARM_ID, 1, b"INS_TCAL2_ENABLE", 1.0)
    rng = np.random.default_rng(12)
    for k in range(n):
        for type_id, dx in ((130, 0.0), (132, 1.0)):
            t = 35.0 + 0.01 * k
            temp = round(t * 100) if temp_format == "c" else t
            out += DF_HEAD + struct.pack("<B", type_id) + struct.pack(
                body, 1_000_000 + 2500 * k, 0.0, 0.0, 0.0, dx + rng.normal(0, 0.01),
                rng.normal(0, 0.01), 9.80665 + rng.normal(0, 0.01), 0, 0, temp, 1, 1, 1000, 1000)
    path.write_bytes(bytes(out))
    return path


def _dataflash_both(path: Path, instance: int = 0) -> tuple:
    from calibration import importers_logs

    taken: list[bool] = []
    real = importers_logs.dataflash_imu_columns

    def spy(*a: object) -> object:
        out = real(*a)
        taken.append(out is not None)
        return out

    results = []
    for fast in (spy, lambda *a: None):
        with pytest.MonkeyPatch.context() as mp:
            mp.setattr(importers_logs, "dataflash_imu_columns", fast)
            try:
                raw = importers_logs.read_dataflash(path, instance=instance)
            except RecordingError as exc:
                results.append(("error", str(exc)))
                continue
        results.append(("ok", raw.t_s.tobytes(), raw.acc_g.tobytes(),
                        None if raw.temp_c is None else raw.temp_c.tobytes(), raw.notes))
    assert results[0] == results[1]
    return results[0], taken[0]


@pytest.mark.parametrize("case", ["with T", "without T", "instance 1 of 2", "instance 3 of 2",
                                  "TCAL on"])
def test_dataflash_fast_path_reads_what_the_message_loop_reads(tmp_path, case):
    from tests.calibration.log_writers import warmup_samples, write_dataflash

    t_us, acc, temp = warmup_samples(n=300)
    kw: dict[str, object] = {}
    if case == "without T":
        temp = None
    if case.startswith("instance"):
        kw["instances"] = 2
    if case == "TCAL on":
        kw["params"] = {"INS_TCAL1_ENABLE": 1.0}
    path = write_dataflash(tmp_path / "log.bin", t_us, acc, temp, **kw)
    instance = int(case.split()[1]) if case.startswith("instance") else 0
    out, taken = _dataflash_both(path, instance)
    assert taken
    assert out[0] == ("error" if case == "instance 3 of 2" else "ok")


@pytest.mark.parametrize("instance,temp_format", [(0, "f"), (1, "f"), (1, "c")])
def test_dataflash_fast_path_old_message_names_and_multipliers(tmp_path, instance, temp_format):
    path = _old_style_dataflash(tmp_path / "old.bin", 200, temp_format=temp_format)
    out, taken = _dataflash_both(path, instance)
    assert taken and out[0] == "ok"
    assert (any("INS_TCAL2_ENABLE" in n for n in out[4])) == (instance == 1)


@pytest.mark.parametrize("layout", ["copter-3.2", "solo", "copter-3.3"])
@pytest.mark.parametrize("instance", [0, 1])
def test_dataflash_fast_path_older_time_and_temperature_fields(tmp_path, layout, instance):
    from tests.calibration.log_writers import warmup_samples, write_dataflash_legacy

    path = write_dataflash_legacy(tmp_path / "old.bin", *warmup_samples(n=200), layout=layout)
    out, taken = _dataflash_both(path, instance)
    assert taken and out[0] == "ok"


def test_dataflash_a_log_cut_off_mid_message_is_left_to_the_loop(tmp_path):
    from tests.calibration.log_writers import warmup_samples, write_dataflash

    path = write_dataflash(tmp_path / "cut.bin", *warmup_samples(n=200))
    path.write_bytes(path.read_bytes()[:-20])
    out, taken = _dataflash_both(path)
    assert not taken and out[0] == "ok"
