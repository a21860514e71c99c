# SPDX-License-Identifier: GPL-3.0-or-later
"""Where gait presets live and how they are listed, saved and removed.

Shipped presets are the JSON files in the extension's ``presets/gait`` folder; they are
read-only. User presets follow Blender's preset convention: they live in the user's
scripts folder under ``presets/procloco/gait`` (``bpy.utils.user_resource``), so they
survive updates of the extension, and can be added and removed from the panel. Both use
the same file format (``docs/DEVELOPING.md``), read and validated by
:func:`procloco_addon.core.locomotion.gait.load_gait_preset`.
"""

from __future__ import annotations

import json
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path

import bpy

from ...core.locomotion import gait as core_gait

__all__ = [
    "PRESET_SUBDIR",
    "PresetEntry",
    "is_user_preset",
    "list_presets",
    "remove_user_preset",
    "save_user_preset",
    "shipped_dir",
    "user_dir",
    "user_preset_path",
]

PRESET_SUBDIR = "procloco/gait"


@dataclass(frozen=True)
class PresetEntry:
    """One preset file as listed in the menu. ``error`` is set when the file is malformed."""

    name: str
    path: Path
    user: bool
    error: str | None = None


def shipped_dir() -> Path:
    """The extension's own presets (read-only)."""
    return core_gait.gait_preset_dir()


def user_dir(*, create: bool = False) -> Path | None:
    """The user's preset folder (``<scripts>/presets/procloco/gait``), or None if Blender has
    no user scripts folder. ``create`` makes it when missing."""
    path = bpy.utils.user_resource("SCRIPTS", path=os.path.join("presets", PRESET_SUBDIR), create=create)
    return Path(path) if path else None


def is_user_preset(path: Path | str) -> bool:
    """True if ``path`` is a file in the user's preset folder (so it may be removed)."""
    folder = user_dir()
    if folder is None:
        return False
    try:
        return Path(path).resolve().parent == folder.resolve()
    except OSError:
        return False


def _display_name(path: Path) -> tuple[str, str | None]:
    """The preset's ``name`` field, or a name from the file name and the reason it failed."""
    try:
        return core_gait.load_gait_preset(path).name, None
    except core_gait.GaitPresetError as error:
        return bpy.path.display_name(path.name), str(error)


def list_presets() -> list[PresetEntry]:
    """Shipped presets then user presets, each group sorted by display name."""
    entries: list[PresetEntry] = []
    folders: list[tuple[Path | None, bool]] = [(shipped_dir(), False), (user_dir(), True)]
    for folder, user in folders:
        if folder is None or not folder.is_dir():
            continue
        group = []
        for path in sorted(folder.glob("*.json")):
            name, error = _display_name(path)
            group.append(PresetEntry(name, path, user, error))
        entries.extend(sorted(group, key=lambda e: e.name.lower()))
    return entries


def user_preset_path(name: str) -> Path:
    """The file a user preset called ``name`` is saved to (the folder is created)."""
    folder = user_dir(create=True)
    if folder is None:
        raise OSError("Blender has no user scripts folder to save presets in")
    stem = bpy.path.clean_name(name.strip()).strip("_").lower() or "gait"
    return folder / f"{stem}.json"


def save_user_preset(preset: core_gait.GaitPreset) -> Path:
    """Write ``preset`` as a user preset (replacing one of the same name) and return its path.

    The file is written to a temporary name first and then moved in place, so a failed
    write never leaves a half-written preset behind.
    """
    path = user_preset_path(preset.name)
    text = json.dumps(preset.to_json(), indent=2) + "\n"
    # Validate what we are about to write with the same reader that will load it.
    core_gait.parse_gait_preset(json.loads(text), path)
    handle, tmp = tempfile.mkstemp(prefix=".procloco-", suffix=".json", dir=path.parent)
    try:
        with os.fdopen(handle, "w", encoding="utf-8") as stream:
            stream.write(text)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    return path


def remove_user_preset(path: Path | str) -> None:
    """Delete a user preset file; shipped presets are refused with ``PermissionError``."""
    target = Path(path)
    if not is_user_preset(target):
        raise PermissionError(f"{target.name} is not a user preset (shipped presets cannot be removed)")
    target.unlink()
