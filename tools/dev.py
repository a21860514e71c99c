#!/usr/bin/env python3
# SPDX-License-Identifier: GPL-3.0-or-later
"""ProcLoco's developer entry point: one script, run with any Python 3.11.

    python3 tools/dev.py example        generate locomotion on examples.blend, write the .blend and a preview
    python3 tools/dev.py example --crowd
                                        the same for the crowd example examples_crowd.blend (60 rigs)
    python3 tools/dev.py test           lint, type-check and run the whole test suite on Blender 5.0,
                                        then the Blender tests on Blender 4.2 LTS (what CI runs)
    python3 tools/dev.py test --portability
                                        the core suite under several BLAS kernels, and once deep
    python3 tools/dev.py build          build the extension zip into dist/
    python3 tools/dev.py lint           ruff and mypy only
    python3 tools/dev.py bench NAME     run benchmarks/bench_NAME.py

``--blender 5.0`` or ``--blender 4.2`` runs any of them on that wheel only (4.2 LTS lives in a
separate ``.venv-4.2``). Each command creates (once) and reuses a virtual environment with the
pinned requirements. Arguments after the command go to pytest (or the script).
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


#: What the 4.2 LTS run of ``test`` covers by default: everything that imports ``bpy``. The core
#: suite is pure numpy with the same pinned numpy on both wheels, so it runs once, on 5.0.
BLENDER_TESTS = ["tests/blender", "tests/farm", "tests/test_packaging.py"]


def run_pytest(python: Path, args: list[str], env: dict[str, str] | None = None) -> int:
    """pytest with ``args``; its exit code 5 (no tests collected) is a failure, not a pass."""
    rc = run([str(python), "-m", "pytest", *args], env=env)
    if rc == 5:
        print("[dev] pytest collected no tests: that is a failure, not a pass", flush=True)
    return rc


def cmd_test(blenders: list[str], extra: list[str]) -> int:
    """Lint and the whole suite on 5.0, then the Blender tests on 4.2 LTS (or one wheel)."""
    rc = 0
    for blender in blenders:
        python = ensure_venv(blender)
        if blender == "5.0":
            lint_rc = cmd_lint(python)
            if lint_rc:
                print("[dev] lint or type check failed", flush=True)
            rc = rc or lint_rc
            args = extra
        else:
            args = extra or (BLENDER_TESTS if len(blenders) > 1 else [])
        print(f"[dev] tests on Blender {blender}", flush=True)
        test_rc = run_pytest(python, args)
        rc = rc or test_rc
    return rc


#: OpenBLAS kernels the portability check runs the core suite under, with the CPU features
#: each needs, as /proc/cpuinfo names them (SSE3 is "pni"): an AVX-512 kernel on a CPU
#: without AVX-512 dies of an illegal instruction.
CORETYPES = {"Haswell": ("avx2", "fma"), "SkylakeX": ("avx512f",), "Prescott": ("pni",)}

#: numpy's own AVX-512 kernels (``exp``, ``arctan2``, ... give other last bits than its AVX2
#: ones): the portability check runs the core suite once more with them off on a CPU that has
#: them, as on a CPU without AVX-512 (unknown names are ignored by numpy).
NUMPY_AVX512 = "AVX512F AVX512CD AVX512_KNL AVX512_KNM AVX512_SKX AVX512_CLX AVX512_CNL AVX512_ICL AVX512_SPR"


def _cpu_flags() -> set[str] | None:
    try:
        text = Path("/proc/cpuinfo").read_text()
    except OSError:
        return None
    for line in text.splitlines():
        if line.startswith("flags"):
            return set(line.split(":", 1)[1].split())
    return None


def _coretype_runs(python: Path, env: dict[str, str]) -> str:
    """'' if BLAS works under ``env``, else why not (a probe process, so a crash is contained)."""
    probe = "import numpy as np; a = np.ones((64, 64)); a @ a; x = np.ones(2); x.dot(x)"
    rc = subprocess.run([str(python), "-c", probe], env=env, capture_output=True).returncode
    return "" if rc == 0 else f"the probe exited with {rc}"


def cmd_portability(extra: list[str]) -> int:
    """The core suite under the machine's own BLAS kernel, each of :data:`CORETYPES` the CPU can
    run, with numpy's AVX-512 kernels off where the CPU has them, and once with
    ``HYPOTHESIS_PROFILE=deep``: numbers must not hang on the CPU."""
    python = ensure_venv("5.0")
    flags = _cpu_flags()
    base = {k: v for k, v in os.environ.items()
            if k not in ("OPENBLAS_CORETYPE", "HYPOTHESIS_PROFILE", "NPY_DISABLE_CPU_FEATURES")}
    runs: list[tuple[str, dict[str, str]]] = [("the machine's own kernel", base)]
    for core, needs in CORETYPES.items():
        env = {**base, "OPENBLAS_CORETYPE": core}
        missing = [f for f in needs if flags is not None and f not in flags]
        why = f"the CPU has no {', '.join(missing)}" if missing else _coretype_runs(python, env)
        if why:
            print(f"[dev] skipping OPENBLAS_CORETYPE={core}: {why}", flush=True)
            continue
        runs.append((f"OPENBLAS_CORETYPE={core}", env))
    if flags is None or "avx512f" in flags:
        runs.append(("numpy without its AVX-512 kernels", {**base, "NPY_DISABLE_CPU_FEATURES": NUMPY_AVX512}))
    runs.append(("HYPOTHESIS_PROFILE=deep", {**base, "HYPOTHESIS_PROFILE": "deep"}))
    results = []
    for name, env in runs:
        print(f"[dev] core suite with {name}", flush=True)
        results.append((name, run_pytest(python, ["-q", "-p", "no:cacheprovider", *(extra or ["tests/core"])],
                                         env=env)))
    for name, rc in results:
        print(f"[dev] {'passed' if rc == 0 else f'FAILED ({rc})'}: {name}", flush=True)
    return 0 if all(rc == 0 for _, rc in results) else 1


def cmd_build(python: Path) -> int:
    (ROOT / "dist").mkdir(exist_ok=True)
    return run([str(python), str(blender_ext_script(python)), "build", "--source-dir", str(ROOT),
                "--output-dir", str(ROOT / "dist")])


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("command", choices=["example", "test", "build", "lint", "bench", "venv"])
    parser.add_argument("--blender", choices=sorted(VENV_DIRS), default=None,
                        help="which bpy wheel to run on (default 5.0; `test` runs 5.0 then 4.2)")
    parser.add_argument("--portability", action="store_true",
                        help="test: the core suite under several OpenBLAS kernels and the deep profile")
    args, extra = parser.parse_known_args(argv)
    os.environ.setdefault("PYTHONDONTWRITEBYTECODE", "1")
    if args.command == "test":
        if args.portability:
            return cmd_portability(extra)
        return cmd_test([args.blender] if args.blender else ["5.0", "4.2"], extra)
    python = ensure_venv(args.blender or "5.0")
    if args.command == "venv":
        print(python)
        return 0
    if args.command == "lint":
        return cmd_lint(python)
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
