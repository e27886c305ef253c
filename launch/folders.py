"""``lamps folders``: the cell's host folders (compose bind mounts) made and given to the service user.

Docker creates a missing bind-mount source as root, where a service running
as an ordinary user (the image's ``lamps``, or ``LAMPS_UID``) cannot write
its credentials, skill or recording. Compose's one-shot ``folders`` service
runs this as root before anything else: each folder is created if missing
and handed to ``--owner`` if root owns it; a folder that belongs to another
user is left alone and, if the owner cannot write it, refused with the fix
(set ``LAMPS_UID`` / ``LAMPS_GID``), rather than failing later in a service.
"""

from __future__ import annotations

import argparse
import os
import stat
import sys
from pathlib import Path


def parse_owner(text: str) -> tuple[int, int]:
    """``UID:GID`` (numbers) -> (uid, gid); ValueError naming the problem."""
    parts = text.split(":")
    if len(parts) != 2 or not all(p.isdigit() for p in parts):
        raise ValueError(f"--owner must be UID:GID in numbers, got {text!r}")
    return int(parts[0]), int(parts[1])


def owner_can_write(st: os.stat_result, uid: int, gid: int) -> bool:
    """Whether uid:gid may create files in a folder with this stat (mode bits; root always may)."""
    mode = st.st_mode
    if uid == 0:
        return True
    if st.st_uid == uid:
        return bool(mode & stat.S_IWUSR and mode & stat.S_IXUSR)
    if st.st_gid == gid:
        return bool(mode & stat.S_IWGRP and mode & stat.S_IXGRP)
    return bool(mode & stat.S_IWOTH and mode & stat.S_IXOTH)


def prepare(folder: Path, uid: int, gid: int) -> str:
    """Make ``folder`` usable by uid:gid; returns what was done. Raises PermissionError saying what to change."""
    if folder.exists() and not folder.is_dir():
        raise NotADirectoryError(f"{folder}: exists and is not a folder")
    made = not folder.exists()
    folder.mkdir(parents=True, exist_ok=True)
    st = folder.stat()
    if st.st_uid == 0 and uid != 0:
        os.chown(folder, uid, gid)
        return f"{folder}: {'made' if made else 'root-owned'}, now owned by {uid}:{gid}"
    if not owner_can_write(st, uid, gid):
        raise PermissionError(f"{folder}: belongs to {st.st_uid}:{st.st_gid} (mode {stat.S_IMODE(st.st_mode):o}) and "
                              f"the services run as {uid}:{gid}, who cannot write it: set LAMPS_UID={st.st_uid} "
                              f"LAMPS_GID={st.st_gid} (the folder's owner) or change its owner")
    return f"{folder}: ok ({st.st_uid}:{st.st_gid})"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="lamps folders", description=__doc__.split("\n\n")[0])
    p.add_argument("folders", nargs="+", metavar="DIR")
    p.add_argument("--owner", required=True, metavar="UID:GID", help="who the services run as")
    p.add_argument("-v", "--verbose", action="store_true", help="say what was done to each folder")
    a = p.parse_args(argv)
    try:
        uid, gid = parse_owner(a.owner)
    except ValueError as exc:
        p.error(str(exc))
    for f in a.folders:
        try:
            what = prepare(Path(f), uid, gid)
        except OSError as exc:
            print(f"lamps folders: error: {exc}", file=sys.stderr)
            return 1
        if a.verbose:
            print(f"lamps folders: {what}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
