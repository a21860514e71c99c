# SPDX-License-Identifier: GPL-3.0-or-later
"""The extension builds, validates, installs, registers and unregisters cleanly.

Blender-side checks run in a fresh interpreter each (``subprocess``), because extension
repositories and enabled add-ons are process-wide state in the ``bpy`` module.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
import textwrap
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


def _bpy_scripts_dir() -> Path:
    import importlib.util

    spec = importlib.util.find_spec("bpy")
    assert spec is not None
    assert spec.submodule_search_locations
    bpy_dir = Path(next(iter(spec.submodule_search_locations)))
    found = sorted(bpy_dir.glob("*/scripts"))
    assert found, "bpy wheel without a scripts folder"
    return found[-1]


def _blender_ext() -> Path:
    return _bpy_scripts_dir() / "addons_core" / "bl_pkg" / "cli" / "blender_ext.py"


def _tags_file() -> Path:
    return _bpy_scripts_dir() / "modules" / "_bpy_internal" / "extensions" / "tags.py"


def _run_python(code: str, tmp_path: Path) -> subprocess.CompletedProcess[str]:
    env = dict(os.environ)
    env["BLENDER_USER_RESOURCES"] = str(tmp_path / "blender-user")
    env["XDG_CACHE_HOME"] = str(tmp_path / "cache")
    env["XDG_CONFIG_HOME"] = str(tmp_path / "config")
    return subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True,
                          env=env, cwd=tmp_path, timeout=300)


def test_core_imports_without_blender(tmp_path: Path) -> None:
    """Every module of procloco_addon.core imports with bpy and mathutils unavailable."""
    code = f"""
        import sys, pkgutil, importlib
        for name in ("bpy", "mathutils", "bmesh", "gpu", "bpy_extras", "blf"):
            sys.modules[name] = None  # makes 'import name' raise ImportError
        sys.path.insert(0, {str(ROOT)!r})
        import procloco_addon.core as core
        names = [m.name for m in pkgutil.walk_packages(core.__path__, "procloco_addon.core.")]
        for name in names:
            importlib.import_module(name)
        assert "bpy" not in sys.modules or sys.modules["bpy"] is None
        print("IMPORTED", len(names) + 1)
    """
    result = _run_python(code, tmp_path)
    assert result.returncode == 0, result.stderr
    assert "IMPORTED" in result.stdout


def test_manifest_validates_with_tags() -> None:
    result = subprocess.run(
        [sys.executable, str(_blender_ext()), "validate", str(ROOT), "--valid-tags", str(_tags_file())],
        capture_output=True, text=True, timeout=120,
    )
    assert result.returncode == 0, result.stdout + result.stderr
    assert "FATAL" not in result.stdout + result.stderr


@pytest.fixture(scope="module")
def built_zip(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("dist")
    result = subprocess.run(
        [sys.executable, str(_blender_ext()), "build", "--source-dir", str(ROOT), "--output-dir", str(out)],
        capture_output=True, text=True, timeout=300,
    )
    assert result.returncode == 0, result.stdout + result.stderr
    zips = list(out.glob("procloco-*.zip"))
    assert len(zips) == 1, result.stdout
    return zips[0]


def test_built_zip_validates_and_excludes_dev_files(built_zip: Path) -> None:
    result = subprocess.run(
        [sys.executable, str(_blender_ext()), "validate", str(built_zip), "--valid-tags", str(_tags_file())],
        capture_output=True, text=True, timeout=120,
    )
    assert result.returncode == 0, result.stdout + result.stderr
    names = zipfile.ZipFile(built_zip).namelist()
    assert "blender_manifest.toml" in names
    assert "__init__.py" in names
    assert "procloco_addon/core/__init__.py" in names
    assert "procloco_addon/blender/render_chunk.py" in names  # the farm's render command ships
    forbidden = ("tests/", "benchmarks/", ".ci/", "tools/", "farm/", ".venv", "pyproject.toml", "__pycache__",
                 ".git/")
    leaked = [n for n in names if any(n.startswith(f) or f"/{f}" in n for f in forbidden)]
    assert leaked == []
    assert [n for n in names if n.endswith(".blend")] == []  # the example scenes are for developers
    # Shipped gait presets travel with the extension.
    assert any(n.startswith("presets/gait/") and n.endswith(".json") for n in names)
    # The README travels with it, and so does every picture it shows.
    assert "README.md" in names
    pictures = re.findall(r"!\[[^\]]*\]\(([^)\s]+)\)", (ROOT / "README.md").read_text())
    assert pictures, "the README shows no pictures?"
    assert [p for p in pictures if p not in names] == []
    assert "docs/DEVELOPING.md" not in names


def test_manifest_names_its_maintainer_with_an_email() -> None:
    import tomllib

    manifest = tomllib.loads((ROOT / "blender_manifest.toml").read_text())
    maintainer = manifest["maintainer"]
    assert re.fullmatch(r"[^<>]+ <[^@\s<>]+@[^@\s<>]+\.[a-z]+>", maintainer), maintainer


_CHECK_REGISTERED = """
    def registered_state(pkg):
        import bpy, importlib
        reg = importlib.import_module(pkg + ".procloco_addon.blender.registration")
        # ``is_registered`` is Blender's own flag; operators and panels also show up in bpy.types.
        classes = {cls.__name__: bool(cls.is_registered) for cls in reg.CLASSES}
        shown = [c.__name__ for c in reg.CLASSES if not issubclass(c, bpy.types.PropertyGroup)]
        assert all(hasattr(bpy.types, n) for n in shown), shown
        pointers = {owner.__name__ + "." + attr: hasattr(owner, attr) for owner, attr, _ in reg.POINTERS}
        return classes, pointers, reg

    def menu_entries(pkg):
        import bpy
        host = bpy.types.VIEW3D_MT_object_animation
        funcs = getattr(host.draw, "_draw_funcs", [])
        return [f for f in funcs if getattr(f, "__module__", "").startswith(pkg)]
"""


def test_zip_installs_registers_and_uninstalls(built_zip: Path, tmp_path: Path) -> None:
    code = _CHECK_REGISTERED + f"""
    import bpy, addon_utils
    bpy.ops.extensions.package_install_files(filepath={str(built_zip)!r}, repo="user_default",
                                             enable_on_install=True)
    pkg = "bl_ext.user_default.procloco"
    assert pkg in {{m.__name__ for m in addon_utils.modules()}}, "not installed"
    assert addon_utils.check(pkg)[1], "installed but not enabled"
    classes, pointers, reg = registered_state(pkg)
    assert classes and all(classes.values()), classes
    assert pointers and all(pointers.values()), pointers
    repos = [r.module for r in bpy.context.preferences.extensions.repos]
    bpy.ops.extensions.package_uninstall(repo_index=repos.index("user_default"), pkg_id="procloco")
    left = [c.__name__ for c in reg.CLASSES if c.is_registered or hasattr(bpy.types, c.__name__)]
    left += [f"{{o.__name__}}.{{a}}" for o, a, _ in reg.POINTERS if hasattr(o, a)]
    assert left == [], left
    print("OK", len(classes))
    """
    result = _run_python(code, tmp_path)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    assert "OK" in result.stdout


def test_enable_from_source_tree_twice_leaves_nothing(tmp_path: Path) -> None:
    repo_dir = tmp_path / "ext_repo"
    repo_dir.mkdir()
    (repo_dir / "procloco").symlink_to(ROOT, target_is_directory=True)
    code = _CHECK_REGISTERED + f"""
    import bpy, addon_utils
    bpy.context.preferences.extensions.repos.new(name="dev", module="dev",
        custom_directory={str(repo_dir)!r}, source="USER")
    pkg = "bl_ext.dev.procloco"
    for attempt in range(2):
        addon_utils.enable(pkg, default_set=True, handle_error=None)
        classes, pointers, reg = registered_state(pkg)
        assert classes and all(classes.values()), (attempt, classes)
        assert all(pointers.values()), (attempt, pointers)
        assert len(menu_entries(pkg)) == 1, (attempt, "the ProcLoco submenu is not in the Animation menu")
        addon_utils.disable(pkg, default_set=True, handle_error=None)
        left = [c.__name__ for c in reg.CLASSES if c.is_registered or hasattr(bpy.types, c.__name__)]
        left += [f"{{o.__name__}}.{{a}}" for o, a, _ in reg.POINTERS if hasattr(o, a)]
        left += [f"menu entry {{f.__name__}}" for f in menu_entries(pkg)]
        assert left == [], (attempt, left)
    print("OK", len(classes))
    """
    result = _run_python(code, tmp_path)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    assert "OK" in result.stdout
