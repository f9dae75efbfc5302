"""docker-compose.yml, checked without Docker: by reading it, then by running its processes.

No Docker engine runs here, so the file is kept correct two ways: its commands
parse with our own CLI parsers and agree with each other and with the rigs
file (ports, time scale, driver URL scheme), and the same three processes it
starts -- `soakcal sim`, `soakcal serve` with the rigs file, the database the
tests use -- are started here as subprocesses and run a campaign over REST.
"""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import time
from pathlib import Path
from typing import Any
from urllib.parse import urlparse

import httpx
import pytest
import yaml

from service.campaigns import load_rigs_file
from service.cli import build_parser
from simulators.cli import build_parser as build_sim_parser

ROOT = Path(__file__).resolve().parents[2]
POSTGRES_ENV = "SOAKCAL_TEST_DATABASE_URL"  # as tests/conftest.py


def _compose() -> dict[str, Any]:
    return yaml.safe_load((ROOT / "docker-compose.yml").read_text())


def _rigs_file(compose: dict[str, Any]) -> Path:
    (mount,) = compose["services"]["soakcal"]["volumes"]
    host_path, container_path, *_ = mount.split(":")
    assert compose["services"]["soakcal"]["environment"]["SOAKCAL_RIGS_FILE"] == container_path
    return ROOT / host_path


def test_compose_commands_parse_and_agree_with_the_rigs_file() -> None:
    compose = _compose()
    services = compose["services"]
    assert set(services) == {"db", "sim-rig", "soakcal"}

    serve = build_parser().parse_args(services["soakcal"]["command"][1:])
    assert serve.command == "serve" and serve.host == "0.0.0.0"
    sim = build_sim_parser().parse_args(services["sim-rig"]["command"][2:])
    assert sim.host == "0.0.0.0"

    db_url = urlparse(services["soakcal"]["environment"]["SOAKCAL_DATABASE_URL"])
    assert db_url.scheme == "postgresql+psycopg"  # the driver the PostgreSQL tests use
    assert db_url.hostname == "db" and db_url.path == "/" + services["db"]["environment"][
        "POSTGRES_DB"]

    rigs = load_rigs_file(str(_rigs_file(compose)))  # raises naming the field if unusable
    (rig,) = rigs
    urls = [rig["chamber"]["url"], rig["turntable"]["url"], rig["sensors"][0]["url"]]
    assert [urlparse(u).hostname for u in urls] == ["sim-rig"] * 3
    assert [urlparse(u).port for u in urls] == [sim.port, sim.port + 1, sim.port + 2]
    assert [str(p) for p in (sim.port, sim.port + 1, sim.port + 2)] == services["sim-rig"][
        "expose"]
    assert rig["chamber"]["time_scale"] == sim.speed
    assert rig["chamber"]["map"] == sim.chamber_map


def test_compose_postgres_is_the_major_version_the_tests_run_on() -> None:
    url = os.environ.get("SOAKCAL_TEST_DATABASE_URL")
    if not url:
        pytest.skip("SOAKCAL_TEST_DATABASE_URL not set")
    from sqlalchemy import create_engine, text

    engine = create_engine(url)
    try:
        with engine.connect() as conn:
            version = conn.execute(text("SHOW server_version")).scalar_one()
    finally:
        engine.dispose()
    image = _compose()["services"]["db"]["image"]
    assert image.split(":")[1] == str(version).split(".")[0]


def _free_base_port() -> int:
    """Three consecutive free TCP ports (the sim's base, +1, +2)."""
    for _ in range(50):
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            base = s.getsockname()[1]
        if base > 65000:
            continue
        try:
            socks = []
            for p in range(base, base + 3):
                so = socket.socket()
                so.bind(("127.0.0.1", p))
                socks.append(so)
            for so in socks:
                so.close()
            return base
        except OSError:
            for so in socks:
                so.close()
    raise RuntimeError("no three consecutive free ports")


def _wait_http(url: str, deadline_s: float, proc: subprocess.Popen, log: Path) -> None:
    """Until ``url`` answers 200; a process that ended first fails with its own output.
    The deadline is generous: a fast machine waits a second, and a loaded CI machine
    importing the service for the first time took over 30 s once."""
    end = time.monotonic() + deadline_s
    while time.monotonic() < end:
        if proc.poll() is not None:
            raise AssertionError(f"the server ended ({proc.returncode}): {log.read_text()}")
        try:
            if httpx.get(url, timeout=1.0).status_code == 200:
                return
        except httpx.HTTPError:
            pass
        time.sleep(0.2)
    raise TimeoutError(f"{url} after {deadline_s:g} s: {log.read_text()}")


SPEED = 3000  # the processes' time scale (compose: 600)


# One backend: the one compose runs (PostgreSQL) where the tests have it, else SQLite. The
# processes' work on each backend is covered in-process by the engine and service tests.
@pytest.mark.parametrize(
    "shared_db_url", ["postgresql" if os.environ.get(POSTGRES_ENV) else "sqlite"], indirect=True)
def test_the_compose_processes_run_a_campaign_without_docker(
    tmp_path: Path, clean_db_url: str
) -> None:
    """sim-rig + serve(rigs file) + the tests' database: a campaign over REST to coefficients."""
    compose = _compose()
    base = _free_base_port()
    rigs = load_rigs_file(str(_rigs_file(compose)))
    # The rig's time and the simulator's at 3000× instead of compose's 600× (the two equal,
    # as the test above checks compose's are): the campaign's soaks and ramps pass 5× faster.
    fast = [{**r, "chamber": {**r["chamber"], "time_scale": SPEED}} for r in rigs]
    text = json.dumps(fast).replace("//sim-rig:", "//127.0.0.1:")
    for k in range(3):  # the compose ports, moved to free ones on this machine
        text = text.replace(f"127.0.0.1:{5020 + k}", f"127.0.0.1:{base + k}")
    (tmp_path / "rigs.json").write_text(text)
    sim_args = compose["services"]["sim-rig"]["command"][1:]
    sim_args[sim_args.index("--host") + 1] = "127.0.0.1"
    sim_args[sim_args.index("--port") + 1] = str(base)
    sim_args[sim_args.index("--speed") + 1] = str(SPEED)
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        api_port = s.getsockname()[1]
    serve_args = compose["services"]["soakcal"]["command"][1:]
    serve_args[serve_args.index("--host") + 1] = "127.0.0.1"
    serve_args[serve_args.index("--port") + 1] = str(api_port)
    serve_args[serve_args.index("--sim-speed") + 1] = str(SPEED)
    env = {**os.environ, "SOAKCAL_DATABASE_URL": clean_db_url,
           "SOAKCAL_RIGS_FILE": str(tmp_path / "rigs.json"), "SOAKCAL_DATA_DIR": str(tmp_path)}
    cli = [sys.executable, "-m", "service.cli"]
    procs = [subprocess.Popen(cli + sim_args, cwd=ROOT, env=env, stdout=subprocess.DEVNULL,
                              stderr=subprocess.DEVNULL)]
    try:
        serve_log = tmp_path / "serve.log"
        with serve_log.open("w") as out:
            procs.append(subprocess.Popen(cli + serve_args, cwd=ROOT, env=env, stdout=out,
                                          stderr=subprocess.STDOUT))
        api = f"http://127.0.0.1:{api_port}/api/v1"
        _wait_http(f"{api}/health", 180.0, procs[-1], serve_log)
        made = subprocess.run(cli + ["token", "create", "--role", "operator"], cwd=ROOT, env=env,
                              capture_output=True, text=True, check=True)
        headers = {"Authorization": f"Bearer {made.stdout.strip().splitlines()[-1]}"}
        (rig_name,) = [r["name"] for r in rigs]
        body = {"rig": rig_name, "sensor": "SN-COMPOSE", "setpoints_c": [15.0, 35.0],
                "positions": "six", "samples_per_position": 20, "soak_min": 20}
        r = httpx.post(f"{api}/campaigns", json=body, headers=headers, timeout=10.0)
        assert r.status_code == 201, r.text
        cid = r.json()["id"]
        end, state = time.monotonic() + 300.0, "queued"  # seconds unloaded; generous
        while time.monotonic() < end and state not in ("completed", "failed", "aborted"):
            time.sleep(0.5)
            camp = httpx.get(f"{api}/campaigns/{cid}", headers=headers, timeout=10.0).json()
            state = camp["state"]
        assert state == "completed", camp
        coef = httpx.get(f"{api}/sensors/SN-COMPOSE/coefficients", headers=headers,
                         params={"temperature_c": 25.0}, timeout=10.0)
        assert coef.status_code == 200, coef.text
        assert coef.json()["calibration_id"] == camp["calibration_id"]
    finally:
        for p in procs:
            p.terminate()
        for p in procs:
            try:
                p.wait(10)
            except subprocess.TimeoutExpired:
                p.kill()
