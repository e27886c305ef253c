"""Skill files: versioned JSON holding everything learned from one demonstration.

Schema (version 1; the full field list is in ``docs/skill_file.md``)::

    {
      "format": "lamps-skill",
      "version": 1,
      "created_utc": "2026-11-22T12:00:00Z",
      "source": {"demo": str, "n_samples": int, "rate_hz": float, "duration_s": float},
      "surface_frame": {"T_surface_to_world": 4x4 list, "rms_off_plane_m": float},
      "segmentation": {"method": str, "threshold": float,
                       "segments": [{"start": int, "end": int, "kind": "periodic"|"transitional",
                                     "cluster": int}]},
      "periodic": [{"segment": int, "cluster": int, "n_cycles": float, "mp": {...}}],
      "transitional": [{"segment": int, "mp": {...}}]
    }

Each ``mp`` is the primitive's own ``to_dict()``; positions inside are
in-plane surface coordinates (x, y) [m]. Loading checks the format tag, the
version and every field, and raises :class:`SkillFileError` naming the
first problem; saving is atomic.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path

from lampskit.atomic import write_text_atomic
from lampskit.core.periodic import PeriodicMP
from lampskit.core.surface import SurfaceFrame
from lampskit.core.transitional import TransitionalMP
from lampskit.errors import LampsError, SkillFileError

FORMAT = "lamps-skill"
VERSION = 1


@dataclass(frozen=True)
class PeriodicEntry:
    """A learned periodic MP and where it came from in the demonstration."""

    segment: int
    cluster: int
    n_cycles: float
    mp: PeriodicMP


@dataclass(frozen=True)
class TransitionalEntry:
    """A learned transitional MP and where it came from in the demonstration."""

    segment: int
    mp: TransitionalMP


@dataclass(frozen=True)
class Skill:
    """Everything learned from one demonstration (see module docstring)."""

    surface: SurfaceFrame
    periodic: tuple[PeriodicEntry, ...]
    transitional: tuple[TransitionalEntry, ...]
    segmentation: dict
    source: dict
    created_utc: str = ""

    def __post_init__(self) -> None:
        if not self.periodic:
            raise SkillFileError("a skill needs at least one periodic MP")

    def to_dict(self) -> dict:
        return {
            "format": FORMAT,
            "version": VERSION,
            "created_utc": self.created_utc or time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
            "source": self.source,
            "surface_frame": self.surface.to_dict(),
            "segmentation": self.segmentation,
            "periodic": [
                {"segment": e.segment, "cluster": e.cluster, "n_cycles": e.n_cycles, "mp": e.mp.to_dict()}
                for e in self.periodic
            ],
            "transitional": [{"segment": e.segment, "mp": e.mp.to_dict()} for e in self.transitional],
        }

    @classmethod
    def from_dict(cls, d: object) -> Skill:
        if not isinstance(d, dict):
            raise SkillFileError(f"a skill file holds a JSON object, got {type(d).__name__}")
        if d.get("format") != FORMAT:
            raise SkillFileError(f"field 'format' must be {FORMAT!r}, got {d.get('format')!r}")
        version = d.get("version")
        if version != VERSION:
            raise SkillFileError(f"unknown skill file version {version!r}; this build reads version {VERSION}")
        for key, kind in (("source", dict), ("surface_frame", dict), ("segmentation", dict), ("periodic", list),
                          ("transitional", list)):
            if not isinstance(d.get(key), kind):
                raise SkillFileError(f"field {key!r} must be a JSON {kind.__name__}, got {type(d.get(key)).__name__}")
        try:
            surface = SurfaceFrame.from_dict(d["surface_frame"])
            periodic = tuple(
                PeriodicEntry(int(e["segment"]), int(e["cluster"]), float(e["n_cycles"]), PeriodicMP.from_dict(e["mp"]))
                for e in _entries(d["periodic"], "periodic")
            )
            transitional = tuple(
                TransitionalEntry(int(e["segment"]), TransitionalMP.from_dict(e["mp"]))
                for e in _entries(d["transitional"], "transitional")
            )
        except SkillFileError:
            raise
        except LampsError as exc:
            raise SkillFileError(f"inconsistent skill: {exc}") from None
        except (KeyError, TypeError, ValueError) as exc:
            raise SkillFileError(f"malformed skill entry: {type(exc).__name__}: {exc}") from None
        return cls(surface, periodic, transitional, d["segmentation"], d["source"], str(d.get("created_utc", "")))


def _entries(items: list, what: str) -> list[dict]:
    for i, e in enumerate(items):
        if not isinstance(e, dict) or "mp" not in e:
            raise SkillFileError(f"{what}[{i}] must be an object with an 'mp' field")
    return items


def save_skill(path: str | Path, skill: Skill) -> Path:
    """Write ``skill`` as JSON, atomically."""
    return write_text_atomic(path, json.dumps(skill.to_dict(), indent=1) + "\n")


def load_skill(path: str | Path) -> Skill:
    """Read and validate a skill file; :class:`SkillFileError` names the problem."""
    path = Path(path)
    if not path.is_file():
        raise SkillFileError(f"{path}: no such skill file")
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise SkillFileError(f"{path}: not valid JSON ({exc})") from None
    try:
        return Skill.from_dict(data)
    except SkillFileError as exc:
        raise SkillFileError(f"{path}: {exc}") from None
