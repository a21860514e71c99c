#!/usr/bin/env python3
# SPDX-License-Identifier: GPL-3.0-or-later
"""ProcLoco's developer entry point: one script, run with any Python 3.11.

    python3 tools/dev.py example        generate locomotion on examples.blend, write the .blend and a preview
    python3 tools/dev.py test           lint, type-check and run the whole test suite
    python3 tools/dev.py build          build the extension zip into dist/
    python3 tools/dev.py lint           ruff and mypy only
    python3 tools/dev.py bench NAME     run benchmarks/bench_NAME.py

``--blender 4.2`` runs any of them on the Blender 4.2 LTS wheel in a separate ``.venv-4.2``.
Each command creates (once) and reuses a virtual environment with the pinned requirements.
"""

from __future__ import annotations

import argparse
import hashlib
import os
import subprocess
import sys
import venv
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
REQUIREMENTS = {"5.0": ROOT / "tools" / "requirements.txt", "4.2": ROOT / "tools" / "requirements-4.2.txt"}
VENV_DIRS = {"5.0": ROOT / ".venv", "4.2": ROOT / ".venv-4.2"}


def venv_python(env_dir: Path) -> Path:
    sub = "Scripts" if os.name == "nt" else "bin"
    exe = "python.exe" if os.name == "nt" else "python"
    return env_dir / sub / exe


def ensure_venv(blender: str) -> Path:
    """Create the virtual environment for ``blender`` if needed; return its interpreter."""
    if sys.version_info[:2] != (3, 11):
        sys.exit(f"ProcLoco's bpy wheels need Python 3.11; this is {sys.version.split()[0]}.")
    env_dir = VENV_DIRS[blender]
    req = REQUIREMENTS[blender]
    digest = hashlib.sha256(req.read_bytes()).hexdigest()
    stamp = env_dir / ".procloco-requirements"
    python = venv_python(env_dir)
    if python.exists() and stamp.exists() and stamp.read_text().strip() == digest:
        return python
    if not python.exists():
        print(f"[dev] creating {env_dir.name} ...", flush=True)
        venv.EnvBuilder(with_pip=True).create(env_dir)
    print(f"[dev] installing {req.name} into {env_dir.name} (bpy is a large wheel) ...", flush=True)
    subprocess.run([str(python), "-m", "pip", "install", "--quiet", "--upgrade", "pip"], check=True)
    subprocess.run([str(python), "-m", "pip", "install", "--quiet", "-r", str(req)], check=True)
    stamp.write_text(digest + "\n")
    return python


def blender_ext_script(python: Path) -> Path:
    """The ``blender_ext.py`` command-line tool shipped inside the bpy wheel."""
    out = subprocess.run(
        [str(python), "-c",
         "import importlib.util as u; print(u.find_spec('bpy').submodule_search_locations[0])"],
        check=True, capture_output=True, text=True,
    )
    bpy_dir = Path(out.stdout.strip())
    found = sorted(bpy_dir.glob("*/scripts/addons_core/bl_pkg/cli/blender_ext.py"))
    if not found:
        sys.exit("blender_ext.py not found inside the bpy wheel")
    return found[-1]


def run(cmd: list[str], **kw: object) -> int:
    print("[dev] $ " + " ".join(str(c) for c in cmd), flush=True)
    return subprocess.run(cmd, cwd=ROOT, **kw).returncode  # type: ignore[call-overload]


def cmd_lint(python: Path) -> int:
    rc = run([str(python), "-m", "ruff", "check", "."])
    rc |= run([str(python), "-m", "mypy"])
    return rc


def cmd_test(python: Path, blender: str, extra: list[str]) -> int:
    rc = 0
    if blender == "5.0":
        rc = cmd_lint(python)
        if rc:
            print("[dev] lint or type check failed", flush=True)
    pytest_rc = run([str(python), "-m", "pytest", *extra])
    if pytest_rc == 5:
        print("[dev] pytest collected no tests: that is a failure, not a pass", flush=True)
        return 5
    return rc or pytest_rc


def cmd_build(python: Path) -> int:
    (ROOT / "dist").mkdir(exist_ok=True)
    return run([str(python), str(blender_ext_script(python)), "build", "--source-dir", str(ROOT),
                "--output-dir", str(ROOT / "dist")])


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("command", choices=["example", "test", "build", "lint", "bench", "venv"])
    parser.add_argument("--blender", choices=sorted(VENV_DIRS), default="5.0",
                        help="which bpy wheel to run on (default 5.0)")
    args, extra = parser.parse_known_args(argv)
    python = ensure_venv(args.blender)
    os.environ.setdefault("PYTHONDONTWRITEBYTECODE", "1")
    if args.command == "venv":
        print(python)
        return 0
    if args.command == "lint":
        return cmd_lint(python)
    if args.command == "test":
        return cmd_test(python, args.blender, extra)
    if args.command == "build":
        return cmd_build(python)
    if args.command == "example":
        return run([str(python), str(ROOT / "tools" / "example.py"), *extra])
    if args.command == "bench":
        if not extra:
            print("usage: dev.py bench NAME [args]   (NAME from benchmarks/bench_NAME.py)")
            return 2
        return run([str(python), str(ROOT / "benchmarks" / f"bench_{extra[0]}.py"), *extra[1:]])
    return 2


if __name__ == "__main__":
    sys.exit(main())
