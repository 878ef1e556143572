"""Saving and loading compiled models: JSON, NumPy ``.npz`` and MATLAB ``.mat``.

Every format carries A, B, C, D (and D1 when present) with the state, input
and output names, and round-trips through :func:`load_model`. Files are
written atomically (temporary file, then rename).
"""

from __future__ import annotations

import io
import json
from pathlib import Path
from typing import Any

import numpy as np
import scipy.io
import scipy.sparse as sp

from netlistdyn.base.atomic import write_bytes
from netlistdyn.base.errors import UsageError
from netlistdyn.statespace.model import CompileInfo, StateSpaceModel

FORMATS = (".json", ".npz", ".mat")


#: Above this many states the matrices are stored sparse (COO triplets in JSON and .npz,
#: MATLAB sparse matrices in .mat): a dense C of a 20 000-state model alone is 3 GiB.
DENSE_SAVE_LIMIT = 2000
#: Most states, inputs or outputs a saved model may name (refused above, before allocating).
MAX_LABELS = 1_000_000
MATRICES = ("A", "B", "C", "D", "D1")


def save_model(model: StateSpaceModel, path: str | Path) -> None:
    """Write ``model`` to ``path``; the suffix picks the format.

    Up to :data:`DENSE_SAVE_LIMIT` states the matrices are dense; above it
    sparse, so the file and the memory needed grow with the non-zeros.
    """
    target = Path(path)
    suffix = target.suffix.lower()
    dense = model.nstates <= DENSE_SAVE_LIMIT
    arrays = {"A": model.A_sparse, "B": model.B_sparse, "C": model.C_sparse, "D": model.D_sparse}
    if model.has_input_derivative:
        arrays["D1"] = model.D1_sparse
    labels = {"states": list(model.states), "inputs": list(model.inputs), "outputs": list(model.outputs)}
    if suffix == ".json":
        matrices = {k: matrix_json(v, dense) for k, v in arrays.items()}
        doc = {"title": model.title, **labels, **matrices}
        write_bytes(path, (json.dumps(doc, indent=None if not dense else 1) + "\n").encode())
    elif suffix == ".npz":
        buffer = io.BytesIO()
        stored: dict[str, np.ndarray] = {}
        for k, v in arrays.items():
            if dense:
                stored[k] = v.toarray()
            else:
                coo = sp.coo_array(v)
                stored.update({f"{k}_shape": np.array(coo.shape), f"{k}_row": coo.row, f"{k}_col": coo.col})
                stored[f"{k}_data"] = coo.data
        # Keywords name the archive's members; typed Any because numpy's stub would also let a
        # dict[str, ndarray] fill savez's allow_pickle: bool.
        members: dict[str, Any] = {
            "title": np.array(model.title),
            **stored,
            **{k: np.array(v, dtype=str) for k, v in labels.items()},
        }
        np.savez(buffer, **members)
        write_bytes(path, buffer.getvalue())
    elif suffix == ".mat":
        buffer = io.BytesIO()
        cells = {k: np.array(v, dtype=object) for k, v in labels.items()}
        mats = {k: v.toarray() if dense else sp.csc_matrix(v) for k, v in arrays.items()}
        scipy.io.savemat(buffer, {**mats, **cells, "title": model.title})
        write_bytes(path, buffer.getvalue())
    else:
        raise UsageError(f"--save {path}: unknown format {suffix!r}; use one of {', '.join(FORMATS)}")


def matrix_json(matrix: sp.sparray, dense: bool) -> Any:
    """A matrix for a JSON document: nested lists of rows (``dense``), else COO triplets.

    Parameters
    ----------
    matrix : scipy.sparse array
        The matrix (its entries in the model's units).
    dense : bool
        Write every entry, row by row, instead of ``{"format": "coo", "shape", "row", "col", "data"}``.

    Returns
    -------
    list or dict
        What :func:`load_model` reads back.
    """
    if dense:
        return matrix.toarray().tolist()
    coo = sp.coo_array(matrix)
    return {
        "format": "coo",
        "shape": list(coo.shape),
        "row": coo.row.tolist(),
        "col": coo.col.tolist(),
        "data": coo.data.tolist(),
    }


class _Bad(Exception):
    """A saved model that cannot be used; the message says why."""


def _labels(raw: Any, key: str) -> tuple[str, ...]:
    if raw is None:
        raise _Bad(f"no {key!r} (the list of {key} names)")
    if isinstance(raw, str | bytes) or not hasattr(raw, "__len__"):
        raise _Bad(f"{key!r} is not a list of names")
    if len(raw) > MAX_LABELS:
        raise _Bad(f"{key!r} names {len(raw):,} {key}, more than {MAX_LABELS:,}")
    names = tuple(str(x) for x in raw)
    if len(set(names)) != len(names):
        raise _Bad(f"{key!r} repeats a name")
    return names


def _matrix(raw: Any, name: str, shape: tuple[int, int], required: bool) -> sp.csr_array:
    """One matrix from a dense nested list/array, COO triplets or a sparse matrix, checked."""
    if raw is None:
        if required:
            raise _Bad(f"no matrix {name}")
        return sp.csr_array(shape)
    if isinstance(raw, dict):
        if raw.get("format") != "coo":
            raise _Bad(f"{name}: unknown matrix format {str(raw.get('format'))[:40]!r}")
        given = tuple(raw.get("shape", ()))
        if given != shape:
            raise _Bad(f"{name} has shape {given}, expected {shape} from the names")
        row, col, data = (np.asarray(raw.get(k, []), dtype=float) for k in ("row", "col", "data"))
        if not (row.ndim == col.ndim == data.ndim == 1 and row.size == col.size == data.size):
            raise _Bad(f"{name}: row, col and data must be lists of equal length")
        if row.size and (
            np.any(row != np.round(row)) or np.any(col != np.round(col)) or row.min() < 0 or col.min() < 0
        ):
            raise _Bad(f"{name}: row and col must be non-negative whole numbers")
        if row.size and (row.max() >= shape[0] or col.max() >= shape[1]):
            raise _Bad(f"{name}: an index lies outside the shape {shape}")
        matrix = sp.csr_array((data, (row.astype(np.int64), col.astype(np.int64))), shape=shape)
    elif sp.issparse(raw):
        if tuple(raw.shape) != shape:
            raise _Bad(f"{name} has shape {tuple(raw.shape)}, expected {shape} from the names")
        matrix = sp.csr_array(raw, dtype=float)
    else:
        array = np.asarray(raw)
        if array.dtype == object or array.dtype.kind not in "biuf":
            raise _Bad(f"{name} is not a matrix of real numbers")
        array = array.astype(float)
        if array.size == 0 and 0 in shape:
            array = np.zeros(shape)
        if array.ndim != 2 or array.shape != shape:
            raise _Bad(f"{name} has shape {array.shape}, expected {shape} from the names")
        matrix = sp.csr_array(array)
    if not np.all(np.isfinite(matrix.data)):
        bad = sp.coo_array(matrix)
        k = int(np.flatnonzero(~np.isfinite(bad.data))[0])
        raise _Bad(f"{name}[{bad.row[k]}, {bad.col[k]}] is {bad.data[k]} (not finite)")
    return matrix


def _read_json(source: Path) -> dict[str, Any]:
    try:
        doc = json.loads(source.read_bytes())
    except json.JSONDecodeError as exc:
        raise _Bad(f"not valid JSON (line {exc.lineno}: {exc.msg})") from None
    except (UnicodeDecodeError, ValueError) as exc:
        raise _Bad(f"not valid JSON ({exc})") from None
    if not isinstance(doc, dict):
        raise _Bad("not a model (a JSON object with states, inputs, outputs, A, B, C, D)")
    return doc


def _read_npz(source: Path) -> dict[str, Any]:
    doc: dict[str, Any] = {}
    with np.load(source, allow_pickle=False) as data:
        if not hasattr(data, "files"):
            raise _Bad("a single array, not a model archive")
        for key in data.files:
            if key in ("states", "inputs", "outputs", "title"):
                doc[key] = data[key].tolist() if data[key].ndim else str(data[key])
        for name in MATRICES:
            if name in data.files:
                doc[name] = data[name]
            elif f"{name}_shape" in data.files:
                doc[name] = {
                    "format": "coo",
                    "shape": [int(x) for x in data[f"{name}_shape"]],
                    **{k: data[f"{name}_{k}"] for k in ("row", "col", "data")},
                }
    for key in ("states", "inputs", "outputs"):
        if isinstance(doc.get(key), str):
            doc[key] = [doc[key]]
    return doc


def _read_mat(source: Path) -> dict[str, Any]:
    data = scipy.io.loadmat(source)
    doc: dict[str, Any] = {}
    for key in ("states", "inputs", "outputs"):
        if key in data:
            cells = np.ravel(data[key])
            doc[key] = [str(np.ravel(x)[0]) if np.size(x) else "" for x in cells]
    if "title" in data:
        doc["title"] = str(np.ravel(data["title"])[0]) if np.size(data["title"]) else ""
    for name in MATRICES:
        if name in data:
            value = data[name]
            doc[name] = value if sp.issparse(value) else np.atleast_2d(value)
    return doc


def load_model(path: str | Path) -> StateSpaceModel:
    """Read a model written by :func:`save_model`, checking it.

    Raises
    ------
    UsageError
        Naming ``path`` and what is wrong: unreadable or corrupt file, a
        missing name list or matrix, a shape that does not match the names,
        a non-finite entry.
    """
    source = Path(path)
    suffix = source.suffix.lower()
    readers = {".json": _read_json, ".npz": _read_npz, ".mat": _read_mat}
    if suffix not in readers:
        raise UsageError(f"{path}: unknown model format {suffix!r}; use one of {', '.join(FORMATS)}")
    kind = suffix[1:]
    try:
        doc = readers[suffix](source)
        labels = {k: _labels(doc.get(k), k) for k in ("states", "inputs", "outputs")}
        n, m, p = (len(labels[k]) for k in ("states", "inputs", "outputs"))
        shapes = {"A": (n, n), "B": (n, m), "C": (p, n), "D": (p, m), "D1": (p, m)}
        mats = {k: _matrix(doc.get(k), k, shapes[k], k != "D1") for k in shapes}
        title = doc.get("title", "")
    except _Bad as exc:
        raise UsageError(f"{path}: bad saved model: {exc}") from None
    except OSError:
        raise
    except MemoryError:
        raise UsageError(f"{path}: bad saved model: too large to load") from None
    except Exception as exc:  # zip, pickle, MATLAB and numpy decoding errors of a corrupt file
        reason = " ".join(str(exc).split())[:120] or type(exc).__name__
        raise UsageError(f"{path}: not a readable .{kind} model ({reason})") from None
    return StateSpaceModel(
        mats["A"],
        mats["B"],
        mats["C"],
        mats["D"],
        mats["D1"],
        labels["states"],
        labels["inputs"],
        labels["outputs"],
        str(title) if isinstance(title, str) else "",
        CompileInfo(order=n),
    )
