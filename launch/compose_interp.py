"""Compose's variables, as the built-in compose reader (:func:`~launch.compose.load_compose`) resolves them: the
interpolation syntax (``$VAR``, ``${VAR}``, ``${VAR:-d}``, ``${VAR-d}``, ``${VAR:?err}``, ``${VAR?err}``,
``${VAR:+x}``, ``${VAR+x}``, nesting, ``$$``), the ``.env`` file beside the compose file (the environment wins) and
the active profiles (``COMPOSE_PROFILES``). What it does not implement it refuses, naming it."""

from __future__ import annotations

import logging
import re
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from interfaces.errors import ConfigError

#: The compose reader's log (as before its variables had a module of their own).
log = logging.getLogger("launch.compose")

_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


# ------------------------------------------------------------------------------------------------ interpolation

def interpolate(text: str, variables: Mapping[str, str], where: str = "compose") -> str:
    """``text`` with compose's variable syntax resolved from ``variables`` (see the module docstring).

    An unset variable without a default is "" (as compose, with a warning in
    the log); a ``$`` followed by neither a name, ``{`` nor ``$`` stays a
    ``$``; a default ends where compose ends it (:func:`_braced`).
    Raises ConfigError for ``${VAR:?err}`` / ``${VAR?err}`` of an unset (or,
    with ``:``, empty) variable, an unclosed ``${``, a ``${`` not followed by
    a name, and operators compose does not know (``${VAR:=x}``,
    ``${VAR#x}`` ...), each naming ``where``.
    """
    return _interp(text, 0, variables, where)


def _interp(text: str, i: int, variables: Mapping[str, str], where: str) -> str:
    """Interpolate ``text`` from ``i`` on."""
    out: list[str] = []
    n = len(text)
    while i < n:
        c = text[i]
        if c != "$":
            out.append(c)
            i += 1
            continue
        if i + 1 < n and text[i + 1] == "$":
            out.append("$")
            i += 2
            continue
        if i + 1 < n and text[i + 1] == "{":
            value, i = _braced(text, i, variables, where)
            out.append(value)
            continue
        m = _NAME.match(text, i + 1)
        if m is None:  # "$5", "$-", a "$" at the end: a plain dollar sign, as compose reads it
            out.append("$")
            i += 1
            continue
        out.append(_lookup(m.group(0), variables, where))
        i = m.end()
    return "".join(out)


def _closing_brace(s: str) -> int:
    """Index in ``s`` (which starts with ``${``) of the brace that closes it, compose's way, or -1.

    Every ``{`` opens one level and hides the character after it, every ``}``
    closes one: odd, but what decides where compose ends a default.
    """
    depth, i = 0, 0
    while i < len(s):
        if s[i] == "}":
            depth -= 1
            if depth == 0:
                return i
        if s[i] == "{":
            depth += 1
            i += 1
        i += 1
    return -1


def _braced(text: str, start: int, variables: Mapping[str, str], where: str) -> tuple[str, int]:
    """``${...}`` beginning at ``start`` (its ``$``); returns (value, index after what it consumed).

    As compose: the expression first reaches the last ``}`` of its line (a
    greedy match), then ends at :func:`_closing_brace` when that is inside;
    the operator is the one right after the name; the argument is itself
    interpolated.
    """
    m = _NAME.match(text, start + 2)
    line_end = text.find("\n", start)
    line_end = len(text) if line_end < 0 else line_end
    last = text.rfind("}", start, line_end)
    op = next((o for o in (":-", ":?", ":+", "-", "?", "+") if m and text.startswith(o, m.end())), None)
    if m is None or last < 0 or (op is None and (m.end() >= len(text) or text[m.end()] != "}")):
        bad = text[start:start + 12]
        raise ConfigError(f"{where}: invalid interpolation format in {text!r} at {bad!r} (compose knows $NAME, "
                          f"${{NAME}} and ${{NAME}} with :- - :? ? :+ +; write $$ for a literal $)")
    name = m.group(0)
    if op is None:
        return _lookup(name, variables, where), m.end() + 1
    greedy = text[start:last + 1]
    close = _closing_brace(greedy)
    end = start + (close if close > -1 else len(greedy) - 1)  # index of the closing brace
    arg_text = text[m.end() + len(op):end]
    value = variables.get(name)
    missing = value is None or (op.startswith(":") and value == "")
    if op.endswith("-"):
        result = _interp(arg_text, 0, variables, where) if missing else (value or "")
    elif op.endswith("?"):
        if missing:
            reason = _interp(arg_text, 0, variables, where)
            raise ConfigError(f"{where}: required variable {name} is missing a value"
                              + (f": {reason}" if reason else ""))
        result = value or ""
    else:  # "+"
        result = (value or "") if missing else _interp(arg_text, 0, variables, where)
    return result, end + 1


def _lookup(name: str, variables: Mapping[str, str], where: str) -> str:
    value = variables.get(name)
    if value is None:
        log.warning("%s: the %s variable is not set; defaulting to a blank string", where, name)
        return ""
    return value


def substitute(text: str, variables: Mapping[str, str]) -> str:
    """:func:`interpolate` (kept for callers of the first reader)."""
    return interpolate(text, variables)


def interpolate_tree(node: Any, variables: Mapping[str, str], where: str) -> Any:
    """Every string value of a parsed YAML tree interpolated (keys are not, as compose)."""
    if isinstance(node, str):
        return interpolate(node, variables, where)
    if isinstance(node, dict):
        return {k: interpolate_tree(v, variables, f"{where}.{k}") for k, v in node.items()}
    if isinstance(node, list):
        return [interpolate_tree(v, variables, where) for v in node]
    return node


# ----------------------------------------------------------------------------------------------------- .env

def read_dotenv(path: Path, environment: Mapping[str, str]) -> dict[str, str]:
    """The variables of a compose ``.env`` file ({} when there is none).

    Implemented: blank and ``#`` lines, ``[export ]KEY=VALUE``; unquoted
    values (trimmed, `` #`` starts a comment, interpolated), ``'single'``
    (literal) and ``"double"`` quoted ones (``\\n \\t \\" \\\\`` escapes,
    interpolated) on one line. Interpolation sees the environment first, then
    the file's earlier keys. Anything else (a line without ``=``, a quote not
    closed on its line) is refused with file and line.
    """
    if not path.is_file():
        return {}
    out: dict[str, str] = {}
    for no, raw in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
        where = f"{path}:{no}"
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        if line.startswith("export "):
            line = line[len("export "):].lstrip()
        key, eq, rest = line.partition("=")
        key = key.strip()
        if not eq or not _NAME.fullmatch(key):
            raise ConfigError(f"{where}: expected KEY=VALUE, got {raw!r}")
        rest = rest.strip()
        seen = {**out, **environment}
        if rest.startswith("'"):
            end = rest.find("'", 1)
            if end < 0:
                raise ConfigError(f"{where}: the single quote is not closed on its line (multi-line values are not "
                                  f"implemented; use docker compose)")
            value = rest[1:end]
            tail = rest[end + 1:].strip()
        elif rest.startswith('"'):
            chars, i = [], 1
            while i < len(rest) and rest[i] != '"':
                if rest[i] == "\\" and i + 1 < len(rest):
                    chars.append({"n": "\n", "t": "\t", '"': '"', "\\": "\\"}.get(rest[i + 1], "\\" + rest[i + 1]))
                    i += 2
                    continue
                chars.append(rest[i])
                i += 1
            if i >= len(rest):
                raise ConfigError(f"{where}: the double quote is not closed on its line (multi-line values are not "
                                  f"implemented; use docker compose)")
            value = interpolate("".join(chars), seen, where)
            tail = rest[i + 1:].strip()
        else:
            cut = re.search(r"\s#", rest)
            value = interpolate((rest[:cut.start()] if cut else rest).strip(), seen, where)
            tail = ""
        if tail and not tail.startswith("#"):
            raise ConfigError(f"{where}: unexpected {tail!r} after the quoted value")
        out[key] = value
    return out


def compose_variables(path: Path, environment: Mapping[str, str]) -> dict[str, str]:
    """What a compose file's interpolation sees: its ``.env`` (beside it), overridden by the environment."""
    return {**read_dotenv(path.parent / ".env", environment), **environment}


def active_profiles(variables: Mapping[str, str]) -> tuple[str, ...]:
    """``COMPOSE_PROFILES`` as a tuple (``*``: every profile)."""
    return tuple(p.strip() for p in variables.get("COMPOSE_PROFILES", "").split(",") if p.strip())
