"""The compose model ``lamps up`` runs: compose's interpolation and ``.env``, the built-in reader against Compose.

The built-in reader (used when Compose v2 is not installed) is compared with
``docker compose config --format json`` on the cell's file, on every
interpolation form, on a few hundred generated templates and on the
refusals: both must give the same services or both refuse.
"""

from __future__ import annotations

import random
import subprocess

import pytest

from interfaces.errors import ConfigError
from launch.compose import compose_model, load_compose, load_with_docker
from launch.compose_interp import active_profiles, interpolate, read_dotenv

from .conftest import REPO
from .docker_helpers import ensure_docker

COMPOSE = REPO / "docker-compose.yml"


# ---------------------------------------------------------------------------------------------- pure rules

@pytest.mark.parametrize("text, variables, expected", [
    ("plain", {}, "plain"),
    ("$A-${A}", {"A": "1"}, "1-1"),
    ("$A_B.c", {"A_B": "x"}, "x.c"),
    ("${A:-d}|${A-d}", {"A": ""}, "d|"),
    ("${A:-d}|${A-d}", {}, "d|d"),
    ("${A:+x}|${A+x}", {"A": ""}, "|x"),
    ("${A:+x}|${A+x}", {"A": "1"}, "x|x"),
    ("${A:+x}|${A+x}", {}, "|"),
    ("${A:?bad}", {"A": "ok"}, "ok"),
    ("${A?bad}", {"A": ""}, ""),
    ("$$A $${A} $$", {"A": "1"}, "$A ${A} $"),
    ("${A:-${B:-${C:-deep}}}", {}, "deep"),
    ("${A:-${B}}", {"B": "b"}, "b"),
    ("${A:-$B-x}", {"B": "b"}, "b-x"),
    ("${A:-a:b-c}", {}, "a:b-c"),
    ("${A:-}", {}, ""),
    ("unset ${NOPE} stays blank", {}, "unset  stays blank"),
    ("${A:-{json}}", {}, "{json}"),  # compose's brace counting
    ("${A:-a{b}c}.", {}, "a{b}c."),
    ("${A+{$B}", {"A": ""}, "{"),  # unbalanced: the default runs to the line's last "}"
    ("${A:-a}b}", {}, "ab}"),
    ("cost $5, end $", {}, "cost $5, end $"),  # a "$" before no name is a dollar sign
    ("a$-b ${A:-$$}", {}, "a$-b $"),
])
def test_interpolation_follows_compose(text, variables, expected):
    assert interpolate(text, variables) == expected


@pytest.mark.parametrize("text, variables, match", [
    ("${A:?is needed}", {}, "required variable A is missing a value: is needed"),
    ("${A:?is needed}", {"A": ""}, "required variable A is missing a value: is needed"),
    ("${A?gone}", {}, "required variable A is missing a value: gone"),
    ("${A?}", {}, "required variable A is missing a value"),
    ("${A:-x", {}, "invalid interpolation format"),
    ("${A:=x}", {}, "invalid interpolation format"),
    ("${A#x}", {}, "invalid interpolation format"),
    ("${1A}", {}, "invalid interpolation format"),
    ("${A:-x\n}", {}, "invalid interpolation format"),  # a default ends on its line
])
def test_what_compose_refuses_is_refused_with_the_reason(text, variables, match):
    with pytest.raises(ConfigError, match=match):
        interpolate(text, variables, where="here")


def test_dotenv_values_quotes_comments_and_interpolation(tmp_path):
    p = tmp_path / ".env"
    p.write_text("# a comment\n\nA=1\nexport B = two words  # comment\nC='literal ${A} # kept'\n"
                 'D="line\\nnext ${A}"\nE=${A}-${HOME_X:-h}\nF=#not-a-comment\nG=\n')
    assert read_dotenv(p, {}) == {"A": "1", "B": "two words", "C": "literal ${A} # kept", "D": "line\nnext 1",
                                  "E": "1-h", "F": "#not-a-comment", "G": ""}
    assert read_dotenv(tmp_path / "none", {}) == {}
    for bad, match in (("NOEQUALS\n", "expected KEY=VALUE"), ("A='open\n", "not closed"),
                       ('A="x" y\n', "unexpected"), ("1A=x\n", "expected KEY=VALUE")):
        p.write_text(bad)
        with pytest.raises(ConfigError, match=r"\.env:1"):
            read_dotenv(p, {})
        with pytest.raises(ConfigError, match=match):
            read_dotenv(p, {})


def test_profiles_come_from_the_environment_then_env_file(tmp_path):
    f = tmp_path / "docker-compose.yml"
    f.write_text("services:\n  a: {image: x, command: [lamps, sim], profiles: [one]}\n"
                 "  b: {image: x, command: [lamps, sim], profiles: [two]}\n  c: {image: x, command: [lamps, sim]}\n")
    (tmp_path / ".env").write_text("COMPOSE_PROFILES=two\n")
    m = compose_model(f, {}, reader="builtin")
    assert m.profiles == ("two",) and [s.name for s in m.active()] == ["b", "c"]
    m = compose_model(f, {"COMPOSE_PROFILES": "one"}, reader="builtin")
    assert [s.name for s in m.active()] == ["a", "c"]
    assert [s.name for s in compose_model(f, {"COMPOSE_PROFILES": "*"}, reader="builtin").active()] == ["a", "b", "c"]
    assert active_profiles({"COMPOSE_PROFILES": " a, ,b "}) == ("a", "b")
    with pytest.raises(ConfigError, match="LAMPS_COMPOSE_READER"):
        compose_model(f, {}, reader="podman")


# ------------------------------------------------------------------------------- the same model as Compose

def _both(path, env):
    """(built-in, docker compose) services of ``path`` with environment ``env``; a refusal as ('error', text)."""
    from launch.compose_interp import compose_variables

    out = []
    for read in (lambda: load_compose(path, compose_variables(path, env)), lambda: load_with_docker(path, env)):
        try:
            out.append(read())
        except ConfigError as exc:
            out.append(("error", str(exc)))
    return out


def test_the_cell_file_reads_the_same_with_compose_and_without():
    ensure_docker()
    for env in ({}, {"LAMPS_SEED": "7", "LAMPS_BOARD": "table", "LAMPS_ACCESS_CONTROL": "false",
                     "LAMPS_HOST_DIR": "/data/cell", "LAMPS_CAMERA_ENDPOINT": "tcp/cam:7000"}):
        builtin, docker = _both(COMPOSE, env)
        assert builtin == docker
        assert list(builtin) == list(docker)  # the file's order, which breaks start-order ties
    m = compose_model(COMPOSE, {})
    assert m.reader.startswith("docker compose ") and m.profiles == ("sim",)  # .env's default profile


def _template(rng: random.Random, depth: int = 0) -> str:
    parts = []
    for _ in range(rng.randint(1, 3)):
        kind = rng.choice(["text", "text", "dollar", "plain", "braced", "op", "op"] if depth < 2 else ["text", "op"])
        name = rng.choice(["SET", "EMPTY", "UNSET", "OTHER"])
        if kind == "text":
            parts.append(rng.choice(["a", "x-y", "1.5", "tcp/h:1", " ", "a:b", "$5", "{", "}", "a{b}c"]))
        elif kind == "dollar":
            parts.append("$$")
        elif kind == "plain":
            parts.append(f"${name}" + rng.choice(["", "/", "."]))
        elif kind == "braced":
            parts.append(f"${{{name}}}")
        else:
            op = rng.choice([":-", "-", ":+", "+"])
            parts.append(f"${{{name}{op}{_template(rng, depth + 1) if rng.random() < 0.5 else 'd'}}}")
    return "".join(parts)


def test_generated_templates_resolve_as_compose_resolves_them(tmp_path):
    ensure_docker()
    rng = random.Random(7)
    env = {"SET": "v", "EMPTY": "", "OTHER": "o"}
    templates = [_template(rng) for _ in range(300)]
    lines = ["services:", "  s:", "    image: x", "    command: [lamps, sim]", "    environment:"]
    lines += [f"      K{i}: '{t}'" for i, t in enumerate(templates)]
    f = tmp_path / "compose.yml"
    f.write_text("\n".join(lines) + "\n")
    (tmp_path / ".env").write_text("OTHER=from-dotenv\nONLY_DOTENV=d\n")
    builtin, docker = _both(f, env)
    assert builtin["s"].environment == docker["s"].environment
    got = builtin["s"].environment
    assert sum(v != templates[int(k[1:])] for k, v in got.items()) > 200  # the templates did get resolved


@pytest.mark.parametrize("value", ["${NEED:?set NEED}", "${A:=x}", "${1A}", "${A:-x", "${A#x}"])
def test_both_readers_refuse_the_same_templates(tmp_path, value):
    ensure_docker()
    f = tmp_path / "compose.yml"
    f.write_text(f"services:\n  s:\n    image: x\n    command: [lamps, sim]\n    environment:\n      K: '{value}'\n")
    builtin, docker = _both(f, {})
    assert isinstance(builtin, tuple) and builtin[0] == "error", builtin
    assert isinstance(docker, tuple) and docker[0] == "error", docker


def test_env_file_reaches_interpolation_in_both_readers_and_the_environment_wins(tmp_path):
    ensure_docker()
    f = tmp_path / "compose.yml"
    f.write_text("services:\n  s:\n    image: x\n    command: [lamps, sim]\n    environment:\n"
                 "      A: ${FROM_FILE}\n      B: ${BOTH}\n      C: ${QUOTED}\n      D: ${CHAINED}\n")
    (tmp_path / ".env").write_text("FROM_FILE=file\nBOTH=file\nQUOTED='a # b'\nCHAINED=${FROM_FILE}-2\n")
    builtin, docker = _both(f, {"BOTH": "shell"})
    assert builtin == docker
    assert builtin["s"].environment == {"A": "file", "B": "shell", "C": "a # b", "D": "file-2"}


def test_lamps_up_reports_which_reader_read_the_file(tmp_path):
    ensure_docker()
    bad = tmp_path / "compose.yml"
    bad.write_text("services:\n  s:\n    image: x\n    command: [lamps, sim]\n"
                   "    environment: {K: '${NEED:?set NEED first}'}\n")
    r = subprocess.run([str(REPO / "lamps"), "up", "--compose", str(bad), "--out", str(tmp_path / "run")],
                       capture_output=True, text=True, timeout=120, cwd=REPO)
    assert r.returncode != 0 and "NEED" in r.stderr and "set NEED first" in r.stderr, r.stderr


def test_lamps_up_reads_the_cell_file_alone_with_the_router_override_in_compose_file():
    """docker-compose.router.yml is compose's alone: COMPOSE_FILE naming it changes nothing ``lamps up`` runs."""
    ensure_docker()
    over = {"COMPOSE_FILE": "docker-compose.yml:docker-compose.router.yml"}
    plain = compose_model(COMPOSE, {})
    for reader in ("docker", "builtin"):
        m = compose_model(COMPOSE, over, reader=reader)
        assert "router" not in m.services and m.services == plain.services, reader
