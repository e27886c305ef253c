"""``lamps up --cells N``: several cells side by side through one ``lamps router``, each a ``lamps up`` of its own.

The launcher makes one CA and every cell's identities (``lamps credentials OUT/credentials --cells ...``:
common names ``<role>@<robot id>``), starts ``lamps router --cells ...`` (the site's access list,
:func:`interfaces.access.site_acl`; its log ``OUT/logs/router.log``), then for cell k (robot id
``<robot-id>-k``, default ``iiwa-1`` ... ``iiwa-N``; seed ``SEED + k - 1``) runs ``lamps up --router ENDPOINT
--credentials OUT/credentials/<robot id> --out OUT/<robot id>``: the same compose services, every one a client
of the router with its cell's identity, the cell's own run folder, recording and ``report.json``
(its output in ``OUT/logs/<robot id>.log``). The skill is learned once, for all cells.

One session of the launcher, the ``site-viewer`` identity (reads every cell, commands none), follows all cells
through the router and prints their progress on one line; at the end one line per cell from its report. Exit 0
only when every cell cleaned its board. Ctrl-C stops every cell the way ``lamps up`` stops one. With
``--foxglove PORT`` one live view serves every cell on PORT (``lamps foxglove --cells``, as the site viewer
through the router; its log ``OUT/logs/foxglove.log``).
"""

from __future__ import annotations

import json
import sys
import time
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

from lampskit.errors import LampsError

if TYPE_CHECKING:
    import zenoh

#: The command every child runs: this interpreter and the console script's module.
LAMPS = (sys.executable, "-m", "runtime.cli")
#: How long a cell's ``lamps up`` may take to stop its services and write its report once asked to.
CELL_STOP_S = 180.0


class SiteError(LampsError):
    """A clear, one-line reason why the cells could not run."""


def _print(line: str) -> None:
    print(line, flush=True)


def cell_ids(robot_id: str, n: int) -> tuple[str, ...]:
    """The robot ids of ``n`` cells: ``<robot_id>-1`` ... ``<robot_id>-n``."""
    return tuple(f"{robot_id}-{k}" for k in range(1, n + 1))


def clients_of_router(services: list, endpoint: str) -> list:
    """The local services (:class:`launch.compose.LocalService`) as clients of the router at ``endpoint``: no
    endpoint of their own, no link to each other."""
    env = {"LAMPS_ZENOH_MODE": "client", "LAMPS_ZENOH_CONNECT": endpoint, "LAMPS_ZENOH_LISTEN": ""}
    return [replace(s, environment={**s.environment, **env}, listen_ports=()) for s in services]


def cell_credentials(a, out: Path) -> Path:
    """The cell's identities: ``--credentials`` (whose cell, if it names one, is the robot id), else new ones (and a
    new CA) in the run folder."""
    from runtime.credentials import cell_of, identity_files, identity_folder, make_credentials

    if not getattr(a, "credentials", None):
        make_credentials(out / "credentials", if_missing=True)
        return out / "credentials"
    credentials = Path(a.credentials).resolve()
    operator = identity_folder(credentials, "operator")
    if not all(f.is_file() for f in identity_files(operator)):
        raise SiteError(f"--credentials {a.credentials}: no operator identity in it (a folder of 'lamps credentials "
                        "DIR', or DIR/<robot id> of 'lamps credentials DIR --cells ...')")
    cell = cell_of(operator)
    if cell and a.robot_id not in (None, cell):
        raise SiteError(f"--credentials {a.credentials} are cell {cell}'s, not --robot-id {a.robot_id}'s")
    a.robot_id = cell or a.robot_id
    return credentials


def run_cells(a, skill: Path, out: Path, stop_requested) -> int:
    """Run ``a.cells`` cells through one router (see the module docstring); the exit code."""
    from interfaces.access import RELAY, SITE_VIEWER
    from interfaces.keys import DEFAULT_ROBOT_ID
    from runtime.credentials import identity_folder, make_credentials

    from .procs import Child, wait_port

    ids = cell_ids(a.robot_id or DEFAULT_ROBOT_ID, a.cells)
    creds = out / "credentials"
    try:
        make_credentials(creds, cells=ids)
    except ValueError as exc:  # a robot id that is no robot id, or names a credentials folder
        raise SiteError(f"--robot-id {a.robot_id}: {exc}") from None
    endpoint = f"tls/127.0.0.1:{_router_port(a.port_base)}"
    echo = _print if a.verbose else None
    children: dict = {}
    try:
        router = children[RELAY] = Child(
            RELAY, (*LAMPS, "router", "--listen", endpoint, "--cells", ",".join(ids), "--status-s", "0"),
            {"LAMPS_ZENOH_IDENTITY": str(identity_folder(creds, RELAY)), "LAMPS_ZENOH_ACCESS_CONTROL": "true"},
            out / "logs", echo)
        if not wait_port(int(endpoint.rsplit(":", 1)[1]), router, 60.0):
            raise SiteError(f"the router did not start: {router.last_words()}")
        if a.foxglove is not None:
            children["foxglove"] = Child(
                "foxglove", (*LAMPS, "foxglove", "--cells", ",".join(ids), "--port", str(a.foxglove), "--connect",
                             endpoint, "-v"),
                {"LAMPS_ZENOH_MODE": "client", "LAMPS_ZENOH_IDENTITY": str(creds / SITE_VIEWER),
                 "LAMPS_ZENOH_ACCESS_CONTROL": "true"}, out / "logs", echo)
        with SiteView(endpoint, creds, ids) as view:
            for k, cell in enumerate(ids):
                children[cell] = Child(cell, _cell_argv(a, k, cell, skill, out, endpoint), {"MPLBACKEND": "Agg"},
                                       out / "logs", echo)
            _print(f"lamps up: cells {', '.join(ids)} through the router at {endpoint}; run folders {out}/<robot id>")
            if a.foxglove is not None:
                _print(f"lamps up: every cell live in Foxglove: Open connection ws://127.0.0.1:{a.foxglove} (layout: "
                       f"lamps foxglove --cells {','.join(ids)} --write-layout FILE)")
            _follow([children[c] for c in ids], view, router, stop_requested)
            _print(f"seen through the router: {view.phases()}")
    finally:
        for name in ids:  # SIGTERM: each lamps up stops its cell as it would on Ctrl-C and writes its report
            if name in children:
                children[name].terminate()
        for name in ids:
            if name in children:
                children[name].stop(CELL_STOP_S)
        if "foxglove" in children:
            children["foxglove"].terminate()
            children["foxglove"].stop()
        if RELAY in children:
            children[RELAY].stop()
    results = [_result(cell, out / cell, children.get(cell)) for cell in ids]
    for line, _ in results:
        _print(line)
    failed = [cell for cell, (_, ok) in zip(ids, results) if not ok]
    if failed:
        print(f"lamps up: {len(failed)} of {len(ids)} cells did not clean their board: {', '.join(failed)}",
              file=sys.stderr)
    return 1 if failed else 0


def _router_port(port_base: int | None) -> int:
    """``--port-base`` (refused if busy), else a free port."""
    from runtime.ports import bindable, free_port

    if port_base is None:
        return free_port()
    if not bindable(port_base):
        raise SiteError(f"the router's port {port_base} is already in use (choose another --port-base)")
    return port_base


def _cell_argv(a, k: int, cell: str, skill: Path, out: Path, endpoint: str) -> tuple[str, ...]:
    """``lamps up`` for cell ``k`` (from 0): the site's options, its own robot id, seed, identities and run folder."""
    argv = [*LAMPS, "up", "--robot-id", cell, "--seed", str(a.seed + k), "--stains", str(a.stains),
            "--board", a.board, "--skill", str(skill), "--mode", a.mode, "--max-duration", str(a.max_duration),
            "--out", str(out / cell), "--router", endpoint, "--credentials", str(out / "credentials" / cell), "-q"]
    if a.robot:
        argv += ["--robot", a.robot]
    if a.compose:
        argv += ["--compose", a.compose]
    return tuple(argv)


def _follow(cells: list, view: SiteView, router, stop_requested) -> None:
    """Print the site's progress every 2 s until every cell's ``lamps up`` has ended (or Ctrl-C)."""
    t0, next_print = time.monotonic(), 0.0
    while any(c.returncode is None for c in cells):
        if stop_requested.is_set():
            _print("lamps up: stopping every cell (Ctrl-C)")
            return
        if router.returncode is not None:
            raise SiteError(f"the router exited with code {router.returncode}: {router.last_words()}")
        now = time.monotonic()
        if now >= next_print:
            next_print = now + 2.0
            _print(f"[cells {now - t0:5.1f} s] {view.progress()}")
        time.sleep(0.1)


def _result(cell: str, run: Path, child) -> tuple[str, bool]:
    """One line for ``cell`` from its ``report.json`` (or why there is none); whether it cleaned its board."""
    report = run / "report.json"
    if not report.is_file():
        why = child.last_words() if child is not None else "not started"
        return f"{cell}: no report ({why})", False
    r = json.loads(report.read_text())
    removed = r.get("dirt_removed_fraction")
    return (f"{cell}: {r['outcome']}, {removed:.1%} of the dirt removed, {r.get('final_phase')} at "
            f"{r.get('sim_time_s') or 0.0:.1f} s robot time ({report})" if removed is not None else
            f"{cell}: {r['outcome']} ({report})"), r["outcome"] == "cleaned"


class SiteView:
    """Every cell's newest controller status and sim truth through the router, in one session as the site viewer.

    endpoint : the router's; creds : the site's credentials folder; cells : the robot ids.
    """

    def __init__(self, endpoint: str, creds: Path, cells: tuple[str, ...]) -> None:
        self.endpoint, self.creds, self.cells = endpoint, creds, cells
        self._readers: dict = {}
        self._status: dict = {}
        self._truth: dict = {}
        self._first_dirt: dict = {}
        self._session: zenoh.Session | None = None

    def __enter__(self) -> SiteView:
        import zenoh

        from interfaces.access import SITE_VIEWER
        from interfaces.keys import Keys
        from interfaces.messages import ControllerStatus, SimTruth
        from runtime.config import ZenohSettings
        from runtime.session import Latest, zenoh_config

        settings = ZenohSettings(mode="client", connect=(self.endpoint,), cells=self.cells, access_control=True,
                                 identity=str(self.creds / SITE_VIEWER))
        try:
            session = self._session = zenoh.open(zenoh_config(settings))
        except zenoh.ZError as exc:
            raise SiteError(f"cannot join the router at {self.endpoint} as {SITE_VIEWER}: {exc}") from None
        for cell in self.cells:
            keys = Keys.for_robot(cell)
            self._readers[cell] = (Latest(session, keys.controller_status, ControllerStatus),
                                   Latest(session, keys.sim_truth, SimTruth))
        return self

    def __exit__(self, *exc) -> None:
        for readers in self._readers.values():
            for r in readers:
                r.close()
        if self._session is not None:
            self._session.close()

    def _update(self) -> None:
        for cell, (status, truth) in self._readers.items():
            self._status[cell] = status.take() or self._status.get(cell)
            self._truth[cell] = tr = truth.take() or self._truth.get(cell)
            if cell not in self._first_dirt and tr is not None and tr.total_dirt > 0:
                self._first_dirt[cell] = tr.total_dirt

    def progress(self) -> str:
        """Every cell's phase and dirt removed (sim truth), as seen through the router."""
        self._update()
        parts = []
        for cell in self.cells:
            st, tr, first = self._status.get(cell), self._truth.get(cell), self._first_dirt.get(cell)
            text = f"{cell} {st.phase}{f' {st.current_mp}' if st.current_mp else ''}" if st else f"{cell} waiting"
            if tr is not None and first:
                text += f" {1.0 - tr.total_dirt / first:.0%} removed"
            parts.append(text)
        return " | ".join(parts)

    def phases(self) -> str:
        """The last phase seen of every cell: ``iiwa-1 DONE, iiwa-2 DONE``."""
        self._update()
        return ", ".join(f"{c} {self._status[c].phase if self._status.get(c) else 'unseen'}" for c in self.cells)
