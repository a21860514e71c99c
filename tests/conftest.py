# SPDX-License-Identifier: GPL-3.0-or-later
"""Shared test setup.

Blender (the ``bpy`` module) must not write into the user's home folder, so its user
resource and cache folders point into a temporary folder before anything imports bpy.
"""

from __future__ import annotations

import os
import sys
import tempfile
from pathlib import Path

import pytest
from hypothesis import HealthCheck, settings

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

_BLENDER_HOME = Path(tempfile.mkdtemp(prefix="procloco-blender-home-"))
os.environ.setdefault("BLENDER_USER_RESOURCES", str(_BLENDER_HOME / "resources"))
os.environ.setdefault("XDG_CACHE_HOME", str(_BLENDER_HOME / "cache"))
os.environ.setdefault("XDG_CONFIG_HOME", str(_BLENDER_HOME / "config"))

# Property tests: bounded and deterministic in CI, deeper on demand (HYPOTHESIS_PROFILE=deep,
# which `tools/dev.py test --portability` runs; also derandomized, so a failure it finds is
# found again on every machine).
settings.register_profile(
    "ci", max_examples=40, deadline=None, derandomize=True,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)
settings.register_profile(
    "deep", max_examples=500, deadline=None, derandomize=True,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))


@pytest.fixture(scope="session")
def repo_root() -> Path:
    return ROOT


def pytest_unconfigure(config: pytest.Config) -> None:
    """On Blender wheels that crash while the interpreter shuts down (4.2), leave with
    pytest's own exit status once everything is reported (see tools/bpy_exit.py)."""
    from tools.bpy_exit import needs_hard_exit

    status = getattr(config, "_procloco_exitstatus", None)
    if status is not None and needs_hard_exit():
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(int(status))


@pytest.hookimpl(trylast=True)
def pytest_sessionfinish(session: pytest.Session, exitstatus: int) -> None:
    session.config._procloco_exitstatus = exitstatus  # type: ignore[attr-defined]
