# SPDX-License-Identifier: GPL-3.0-or-later
"""A stand-in for the ``blender`` executable in the farm tests, which have only the ``bpy``
module (Blender as a Python module has no command line).

It accepts exactly the command lines the farm job definitions run ProcLoco with::

    blender [-b | --background] [-y | --enable-autoexec] FILE --command procloco ARGS...

and does what Blender's binary does with them: ProcLoco enabled (as the extension
installed on a worker would be), FILE opened, then the ``procloco`` command called with
ARGS; its return value is the exit status. Anything else exits with status 2 and says so.
"""

from __future__ import annotations

import os
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def main(argv: list[str]) -> int:
    args = list(argv)
    while args and args[0] in ("-b", "--background", "-y", "--enable-autoexec"):
        args.pop(0)
    if len(args) < 3 or args[1:3] != ["--command", "procloco"]:
        print(f"fake blender: only '-b [-y] FILE --command procloco ...' is supported, not {argv}",
              file=sys.stderr, flush=True)
        return 2
    blendfile, command = args[0], args[3:]
    home = Path(tempfile.mkdtemp(prefix="procloco-fake-blender-"))
    os.environ.setdefault("BLENDER_USER_RESOURCES", str(home / "resources"))
    os.environ.setdefault("XDG_CACHE_HOME", str(home / "cache"))
    sys.path.insert(0, str(ROOT))
    import bpy

    import procloco_addon
    from procloco_addon.blender import cli

    procloco_addon.register()
    try:
        bpy.ops.wm.open_mainfile(filepath=blendfile)
    except RuntimeError as err:  # a file that cannot be read ends the run
        print(f"fake blender: {err}", file=sys.stderr, flush=True)
        return 1
    return cli.main(command)


if __name__ == "__main__":
    status = main(sys.argv[1:])
    sys.stdout.flush()
    sys.stderr.flush()
    # Some bpy wheels (4.2) crash while the interpreter shuts down: leave at once.
    os._exit(status)
