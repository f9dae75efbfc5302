"""Helpers of the browser tests: the live service's address and tokens, Chromium or skip."""

from __future__ import annotations

import shutil
from dataclasses import dataclass
from pathlib import Path

import pytest

CHROMIUM = Path("/usr/bin/chromium")


@dataclass
class LiveService:
    url: str
    tokens: dict[str, str]


def chromium_or_skip() -> str:
    """Debian's chromium and the playwright package, or skip with the reason."""
    if not CHROMIUM.exists() and not shutil.which("chromium"):
        pytest.skip("no Chromium (apt-get install chromium; .ci/run installs it)")
    pytest.importorskip("playwright.sync_api", reason="pip install playwright (test extra)")
    return str(CHROMIUM if CHROMIUM.exists() else shutil.which("chromium"))
