"""Reading and writing demonstrations and their labels.

Formats, chosen by the file name:

- ``.csv``: a header row with ``t,x,y,z`` (seconds, metres) and optionally
  ``qx,qy,qz,qw`` (scalar-last unit quaternion); extra columns are ignored.
- ``.npz``: arrays ``t`` (T,), ``position`` (T, 3) and optionally
  ``orientation_wxyz`` (T, 4).
- ``.tsv``: a Qualisys QTM 3D export (header lines such as ``NO_OF_FRAMES``,
  ``FREQUENCY``, ``MARKER_NAMES``; millimetres; a missing marker is a
  ``0 0 0`` triple or empty/NaN). The eraser carries three or more markers;
  the tool pose is their rigid-body fit (:func:`tool_pose_from_markers`).
- ``.mat``: the four real demonstrations of ``circular_wiping_dataset.mat``
  (see ``../shared/data/wiping-demos/README.md``); pick one with
  ``file.mat#INDEX`` (default 0).

Labels (for ``lamps evaluate-segmentation``): a ``.csv`` with a ``label``
column (``periodic`` / ``transitional``) or a ``periodic`` column (1 / 0),
an ``.npz`` with ``true_periodic``, or ``file.mat#INDEX`` (state 2 =
periodic). Every problem raises :class:`~lampskit.errors.DemoError`
naming the file and what is wrong; writers are atomic.
"""

from __future__ import annotations

import csv
import io
from pathlib import Path
from typing import Any

import numpy as np

from lampskit.atomic import write_atomic, write_text_atomic
from lampskit.core.rotations import quat_wxyz_from_matrix
from lampskit.errors import DemoError
from lampskit.learn.demo import Demonstration

#: Longest marker gap [s] that is bridged by interpolation in a QTM export.
MAX_MARKER_GAP_S = 0.1
#: Largest RMS residual [m] of the rigid-body fit before a frame is rejected.
MAX_FIT_RESIDUAL_M = 0.005


def split_index(spec: str | Path) -> tuple[Path, int | None]:
    """``"file.mat#2"`` -> (Path("file.mat"), 2); no ``#`` -> (path, None)."""
    text = str(spec)
    if "#" in text:
        base, _, idx = text.rpartition("#")
        try:
            return Path(base), int(idx)
        except ValueError:
            raise DemoError(f"{text}: the part after '#' must be a demonstration index, got {idx!r}") from None
    return Path(text), None


def read_demo(spec: str | Path) -> Demonstration:
    """Read a demonstration; the format follows the file name (see module docstring)."""
    path, index = split_index(spec)
    if not path.is_file():
        raise DemoError(f"{path}: no such file")
    suffix = path.suffix.lower()
    if index is not None and suffix != ".mat":
        raise DemoError(f"{spec}: '#INDEX' is only meaningful for .mat files")
    readers = {".csv": _read_csv, ".npz": _read_npz, ".tsv": _read_qtm_tsv, ".mat": _read_mat}
    if suffix not in readers:
        raise DemoError(f"{path}: unknown demonstration format {suffix!r}; valid: {', '.join(readers)}")
    if path.stat().st_size == 0:
        raise DemoError(f"{path}: the file is empty")
    if suffix == ".mat":
        return _read_mat(path, index or 0)
    return readers[suffix](path)


def read_labels(spec: str | Path, n_samples: int) -> np.ndarray:
    """Per-sample truth, shape (n_samples,), True where the sample is periodic."""
    path, index = split_index(spec)
    if not path.is_file():
        raise DemoError(f"{path}: no such file")
    suffix = path.suffix.lower()
    if suffix == ".mat":
        labels = np.asarray(_load_mat(path)["True_states"][index or 0]).ravel() == 2
    elif suffix == ".npz":
        with _open_npz(path) as z:
            if "true_periodic" not in z:
                raise DemoError(f"{path}: missing array 'true_periodic'; has {sorted(z.files)}")
            labels = np.asarray(z["true_periodic"]).astype(bool).ravel()
    elif suffix == ".csv":
        header, rows = _csv_rows(path)
        if "label" in header:
            col = [r[header.index("label")].strip().lower() for r in rows]
            bad = sorted({c for c in col if c not in ("periodic", "transitional")})
            if bad:
                raise DemoError(f"{path}: label must be 'periodic' or 'transitional', got {bad[:3]}")
            labels = np.array([c == "periodic" for c in col])
        elif "periodic" in header:
            labels = np.array([r[header.index("periodic")].strip() not in ("0", "false", "False") for r in rows])
        else:
            raise DemoError(f"{path}: missing column 'label' (or 'periodic'); header is {header}")
    else:
        raise DemoError(f"{path}: unknown label format {suffix!r}; valid: .csv, .npz, .mat")
    if len(labels) != n_samples:
        raise DemoError(f"{path}: {len(labels)} labels for a demonstration of {n_samples} samples")
    return labels


def write_demo_csv(path: str | Path, demo: Demonstration) -> Path:
    """Write ``demo`` as CSV (``t,x,y,z[,qx,qy,qz,qw]``), atomically."""
    buf = io.StringIO()
    cols = ["t", "x", "y", "z"]
    data = [demo.t_s[:, None], demo.position_m]
    if demo.orientation_wxyz is not None:
        cols += ["qx", "qy", "qz", "qw"]
        data.append(demo.orientation_wxyz[:, [1, 2, 3, 0]])
    np.savetxt(buf, np.hstack(data), delimiter=",", header=",".join(cols), comments="", fmt="%.9g")
    return write_text_atomic(path, buf.getvalue())


def write_demo_npz(path: str | Path, demo: Demonstration) -> Path:
    """Write ``demo`` as NPZ, atomically."""
    arrays: dict[str, Any] = {"t": demo.t_s, "position": demo.position_m}
    if demo.orientation_wxyz is not None:
        arrays["orientation_wxyz"] = demo.orientation_wxyz
    return write_atomic(path, lambda f: np.savez(f, **arrays))


def write_labels_csv(path: str | Path, t_s: np.ndarray, periodic: np.ndarray, stain: np.ndarray) -> Path:
    """Write per-sample truth (``t,label,stain``) atomically."""
    lines = ["t,label,stain"]
    lines += [f"{t:.9g},{'periodic' if p else 'transitional'},{s}" for t, p, s in zip(t_s, periodic, stain)]
    return write_text_atomic(path, "\n".join(lines) + "\n")


# --------------------------------------------------------------------------
# readers


def _csv_rows(path: Path) -> tuple[list[str], list[list[str]]]:
    with open(path, newline="", encoding="utf-8-sig") as f:
        rows = [r for r in csv.reader(f) if r and any(c.strip() for c in r)]
    if not rows:
        raise DemoError(f"{path}: the file is empty")
    header = [c.strip().lower() for c in rows[0]]
    if not rows[1:]:
        raise DemoError(f"{path}: a header but no data rows")
    return header, rows[1:]


def _read_csv(path: Path) -> Demonstration:
    header, rows = _csv_rows(path)
    need = ["t", "x", "y", "z"]
    missing = [c for c in need if c not in header]
    if missing:
        raise DemoError(f"{path}: missing column(s) {missing}; need {need} (header is {header})")
    quat = ["qx", "qy", "qz", "qw"]
    has_q = [c in header for c in quat]
    if any(has_q) and not all(has_q):
        raise DemoError(f"{path}: orientation needs all of {quat}; missing {[c for c, h in zip(quat, has_q) if not h]}")
    cols = need + (quat if all(has_q) else [])
    idx = [header.index(c) for c in cols]
    data = np.empty((len(rows), len(cols)))
    for i, row in enumerate(rows):
        if len(row) < len(header):
            raise DemoError(f"{path}: line {i + 2} has {len(row)} fields, the header has {len(header)}")
        for j, k in enumerate(idx):
            try:
                data[i, j] = float(row[k])
            except ValueError:
                raise DemoError(f"{path}: line {i + 2}, column {cols[j]!r}: {row[k]!r} is not a number") from None
    q = data[:, [7, 4, 5, 6]] if all(has_q) else None
    return Demonstration(data[:, 0], data[:, 1:4], q, source=str(path))


def _open_npz(path: Path):
    try:
        return np.load(path, allow_pickle=False)
    except Exception as exc:  # numpy raises several types for a corrupt archive
        raise DemoError(f"{path}: not a readable .npz archive ({exc})") from None


def _read_npz(path: Path) -> Demonstration:
    with _open_npz(path) as z:
        missing = [k for k in ("t", "position") if k not in z.files]
        if missing:
            raise DemoError(f"{path}: missing array(s) {missing}; has {sorted(z.files)}")
        q = z["orientation_wxyz"] if "orientation_wxyz" in z.files else None
        return Demonstration(z["t"], z["position"], q, source=str(path))


def _load_mat(path: Path) -> dict:
    from scipy.io import loadmat

    try:
        m = loadmat(path, squeeze_me=True, struct_as_record=False)
    except Exception as exc:  # scipy raises several types for a corrupt file
        raise DemoError(f"{path}: not a readable MATLAB file ({exc})") from None
    for key in ("proc_data", "True_states"):
        if key not in m:
            raise DemoError(f"{path}: missing variable {key!r} (expected the wiping-demos layout)")
    return m


def _read_mat(path: Path, index: int = 0) -> Demonstration:
    data = np.atleast_1d(_load_mat(path)["proc_data"])
    if not 0 <= index < len(data):
        raise DemoError(f"{path}: demonstration index {index} out of range 0..{len(data) - 1}")
    d = data[index]
    X = np.asarray(d.X, dtype=float)
    n = X.shape[1]
    t = np.arange(n) * float(d.dt)
    # The dataset's quaternion rows 3:7 are scalar-first.
    return Demonstration(t, X[:3].T, X[3:7].T, source=f"{path}#{index}")


def _read_qtm_tsv(path: Path) -> Demonstration:
    with open(path, encoding="utf-8-sig", errors="replace") as f:
        lines = [ln.rstrip("\r\n") for ln in f]
    meta: dict[str, list[str]] = {}
    i = 0
    while i < len(lines):
        fields = lines[i].split("\t")
        key = fields[0].strip()
        if key and key.replace("_", "").isupper() and not _is_number(key):
            meta[key] = fields[1:]
            i += 1
        else:
            break
    for key in ("FREQUENCY", "MARKER_NAMES"):
        if key not in meta:
            raise DemoError(f"{path}: not a QTM 3D export: header line {key!r} missing")
    try:
        rate = float(meta["FREQUENCY"][0])
    except (IndexError, ValueError):
        raise DemoError(f"{path}: FREQUENCY {meta['FREQUENCY']!r} is not a number") from None
    names = [n for n in meta["MARKER_NAMES"] if n.strip()]
    if len(names) < 3:
        raise DemoError(f"{path}: {len(names)} marker(s) {names}; the eraser needs at least 3 for a rigid-body fit")
    body = lines[i:]
    has_time = False
    if body and body[0].split("\t")[0].strip().lower() == "frame":
        has_time = len(body[0].split("\t")) > 1 and body[0].split("\t")[1].strip().lower() == "time"
        body = body[1:]
    elif body and body[0] and not _is_number(body[0].split("\t")[0]):
        body = body[1:]  # some other column header
    rows = [ln.split("\t") for ln in body if ln.strip()]
    if not rows:
        raise DemoError(f"{path}: the QTM export has no data rows")
    width = 3 * len(names)
    lead = 2 if has_time else 0
    data = np.full((len(rows), lead + width), np.nan)
    for r, fields in enumerate(rows):
        if len(fields) < lead + width:
            raise DemoError(f"{path}: data row {r + 1} has {len(fields)} fields, need {lead + width}")
        for c in range(lead + width):
            text = fields[c].strip()
            if text == "" or text.lower() == "nan":
                continue
            try:
                data[r, c] = float(text)
            except ValueError:
                raise DemoError(f"{path}: data row {r + 1}, field {c + 1}: {text!r} is not a number") from None
    t = data[:, 1] if has_time else np.arange(len(rows)) / rate
    markers = data[:, lead:].reshape(len(rows), len(names), 3) / 1000.0  # mm -> m
    markers[np.all(markers == 0.0, axis=2)] = np.nan  # QTM writes 0 0 0 for an unseen marker
    try:
        pos, quat = tool_pose_from_markers(markers, t)
    except DemoError as exc:
        raise DemoError(f"{path}: {exc}") from None
    return Demonstration(t, pos, quat, source=str(path))


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


# --------------------------------------------------------------------------
# rigid-body fit


def tool_pose_from_markers(markers_m: np.ndarray, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Tool pose from markers on a rigid body, frame by frame (Kabsch fit).

    The body frame is defined by the first frame in which every marker is
    seen: origin at the markers' centroid, axes along the principal axes of
    the marker layout (largest spread first, right-handed). Each frame with at
    least three markers seen is fitted by least squares; gaps up to
    :data:`MAX_MARKER_GAP_S` are bridged by interpolation.

    Parameters
    ----------
    markers_m : array, shape (T, M, 3)
        Marker positions [m]; NaN where a marker was not seen.
    t_s : array, shape (T,)
        Frame times [s].

    Returns
    -------
    position_m : array, shape (T, 3)
        Body-frame origin in the capture frame [m].
    orientation_wxyz : array, shape (T, 4)
        Body orientation, scalar-first unit quaternions.
    """
    T, M, _ = markers_m.shape
    seen = np.all(np.isfinite(markers_m), axis=2)
    full = np.flatnonzero(seen.all(axis=1))
    if full.size == 0:
        raise DemoError("no frame sees every marker, so the marker layout on the eraser is unknown")
    ref = markers_m[full[0]]
    centroid = ref.mean(axis=0)
    _, _, vt = np.linalg.svd(ref - centroid)
    axes = vt.copy()
    if np.linalg.det(axes) < 0:
        axes[2] *= -1
    layout = (ref - centroid) @ axes.T  # marker positions in the body frame, (M, 3)
    pos = np.full((T, 3), np.nan)
    quat = np.full((T, 4), np.nan)
    for k in range(T):
        m = seen[k]
        if m.sum() < 3:
            continue
        R, p, rms = _kabsch(layout[m], markers_m[k, m])
        if rms > MAX_FIT_RESIDUAL_M:
            raise DemoError(
                f"rigid-body fit residual {rms * 1000:.1f} mm at frame {k} exceeds "
                f"{MAX_FIT_RESIDUAL_M * 1000:.0f} mm (swapped or mislabelled marker?)"
            )
        pos[k] = p
        quat[k] = quat_wxyz_from_matrix(R)
    good = np.isfinite(pos[:, 0])
    if not good.any():
        raise DemoError("no frame sees three or more markers")
    _bridge_gaps(t_s, good)
    # keep quaternion signs continuous before interpolating
    gi = np.flatnonzero(good)
    for a, b in zip(gi[:-1], gi[1:]):
        if np.dot(quat[a], quat[b]) < 0:
            quat[b] = -quat[b]
    for d in range(3):
        pos[:, d] = np.interp(t_s, t_s[good], pos[good, d])
    for d in range(4):
        quat[:, d] = np.interp(t_s, t_s[good], quat[good, d])
    quat /= np.linalg.norm(quat, axis=1, keepdims=True)
    return pos, quat


def _bridge_gaps(t_s: np.ndarray, good: np.ndarray) -> None:
    bad = np.flatnonzero(~good)
    if bad.size == 0:
        return
    starts = bad[np.r_[True, np.diff(bad) > 1]]
    ends = bad[np.r_[np.diff(bad) > 1, True]]
    for a, b in zip(starts, ends):
        before = t_s[a - 1] if a > 0 else t_s[a]
        after = t_s[b + 1] if b + 1 < len(t_s) else t_s[b]
        if a == 0 or b + 1 == len(t_s) or after - before > MAX_MARKER_GAP_S:
            raise DemoError(
                f"fewer than three markers seen from t={t_s[a]:.3f} s to t={t_s[b]:.3f} s "
                f"(frames {a}-{b}); gaps longer than {MAX_MARKER_GAP_S} s or at the ends are not bridged"
            )


def _kabsch(body: np.ndarray, world: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """R, p minimising sum |R body_i + p - world_i|^2, and the RMS residual [m]."""
    cb, cw = body.mean(axis=0), world.mean(axis=0)
    H = (body - cb).T @ (world - cw)
    U, _, Vt = np.linalg.svd(H)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T))])
    R = Vt.T @ D @ U.T
    p = cw - R @ cb
    rms = float(np.sqrt(np.mean(np.sum((body @ R.T + p - world) ** 2, axis=1))))
    return R, p, rms
