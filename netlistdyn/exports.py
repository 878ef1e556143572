"""Saving and loading compiled models: JSON, NumPy ``.npz`` and MATLAB ``.mat``.

Every format carries A, B, C, D (and D1 when present) with the state, input
and output names, and round-trips through :func:`load_model`. Files are
written atomically (temporary file, then rename).
"""

from __future__ import annotations

import io
import json
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from .atomic import write_bytes
from .errors import UsageError
from .model import CompileInfo, StateSpaceModel

FORMATS = (".json", ".npz", ".mat")


def save_model(model: StateSpaceModel, path: str | Path) -> None:
    """Write ``model`` to ``path``; the suffix picks the format."""
    target = Path(path)
    suffix = target.suffix.lower()
    arrays = {"A": model.A, "B": model.B, "C": model.C, "D": model.D}
    if model.has_input_derivative:
        arrays["D1"] = model.D1
    labels = {"states": list(model.states), "inputs": list(model.inputs), "outputs": list(model.outputs)}
    if suffix == ".json":
        doc = {"title": model.title, **labels, **{k: v.tolist() for k, v in arrays.items()}}
        write_bytes(target, (json.dumps(doc, indent=1) + "\n").encode())
    elif suffix == ".npz":
        buffer = io.BytesIO()
        np.savez(
            buffer,
            title=np.array(model.title),
            **{k: np.array(v) for k, v in arrays.items()},
            **{k: np.array(v, dtype=str) for k, v in labels.items()},
        )
        write_bytes(target, buffer.getvalue())
    elif suffix == ".mat":
        import scipy.io

        buffer = io.BytesIO()
        cells = {k: np.array(v, dtype=object) for k, v in labels.items()}
        scipy.io.savemat(
            buffer, {**{k: np.array(v) for k, v in arrays.items()}, **cells, "title": model.title}
        )
        write_bytes(target, buffer.getvalue())
    else:
        raise UsageError(f"--save {path}: unknown format {suffix!r}; use one of {', '.join(FORMATS)}")


def load_model(path: str | Path) -> StateSpaceModel:
    """Read a model written by :func:`save_model`."""
    source = Path(path)
    suffix = source.suffix.lower()
    if suffix == ".json":
        doc = json.loads(source.read_text())
        arrays = {k: np.array(doc[k], dtype=float) for k in ("A", "B", "C", "D", "D1") if k in doc}
        labels = {k: tuple(doc[k]) for k in ("states", "inputs", "outputs")}
        title = doc.get("title", "")
    elif suffix == ".npz":
        with np.load(source, allow_pickle=False) as data:
            arrays = {k: data[k] for k in ("A", "B", "C", "D", "D1") if k in data}
            labels = {k: tuple(str(x) for x in data[k]) for k in ("states", "inputs", "outputs")}
            title = str(data["title"])
    elif suffix == ".mat":
        import scipy.io

        data = scipy.io.loadmat(source)
        arrays = {k: np.atleast_2d(data[k]).astype(float) for k in ("A", "B", "C", "D", "D1") if k in data}
        labels = {
            k: tuple(str(np.ravel(x)[0]) if np.size(x) else "" for x in np.ravel(data[k]))
            for k in ("states", "inputs", "outputs")
        }
        title = str(np.ravel(data["title"])[0]) if data["title"].size else ""
    else:
        raise UsageError(f"{path}: unknown model format {suffix!r}")
    n, m, p = len(labels["states"]), len(labels["inputs"]), len(labels["outputs"])
    shapes = {"A": (n, n), "B": (n, m), "C": (p, n), "D": (p, m), "D1": (p, m)}
    mats = {
        k: sp.csr_array(np.asarray(arrays.get(k, np.zeros(shapes[k]))).reshape(shapes[k])) for k in shapes
    }
    return StateSpaceModel(
        mats["A"],
        mats["B"],
        mats["C"],
        mats["D"],
        mats["D1"],
        labels["states"],
        labels["inputs"],
        labels["outputs"],
        title,
        CompileInfo(order=n),
    )
