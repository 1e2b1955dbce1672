"""Vector-field models and their files: ``.json`` or pickle-free ``.npz`` <->
:class:`VectorFieldModel`.

A model file holds the fields (as their ``to_yaml`` documents) and the demonstration points they
were fitted on; it is plain data, never a pickle, so loading one runs no code.
"""

from __future__ import annotations

import io
import json
import zipfile
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .errors import SkillError
from .fields import Field
from .registry import ByValue, unit_divisor

Array = NDArray[np.float64]

MAX_MODEL_BYTES = 256 * 1024 * 1024  # arrays of one .npz model file, uncompressed


@dataclass(frozen=True, eq=False)
class VectorFieldModel(ByValue):
    """Fields plus the demonstration points they were fitted on (model file data).

    ``points`` (n, 3) positions of the mapping's frame in the object frame,
    ``quaternions`` (n, 4) orientations (x, y, z, w) of that frame, and
    ``responsibilities`` (n, K) the EM membership of each point in each field.
    """

    fields: tuple[Field, ...]
    points: Array
    quaternions: Array
    responsibilities: Array


def vector_field_model_from_bytes(data: bytes, rel: str, where: str) -> VectorFieldModel:
    """Parse a vector-field model file (``.json`` or pickle-free ``.npz``)."""
    if rel.endswith(".json"):
        try:
            doc = json.loads(data)
        except (ValueError, UnicodeDecodeError) as exc:
            raise SkillError(where, "", f"invalid JSON ({exc})") from None
        except RecursionError:
            raise SkillError(where, "", "invalid JSON (nested too deeply)") from None
        if not isinstance(doc, dict):
            raise SkillError(where, "", "expected a JSON object")
        fields_doc = doc.get("fields")
        arrays = {k: doc.get(k) for k in ("points", "quaternions", "responsibilities")}
    elif rel.endswith(".npz"):
        arrays, fields_doc = _npz_arrays(data, where)
    else:
        raise SkillError(where, "", "model files must be .json or .npz")

    def array(key: str, cols: int) -> np.ndarray:
        try:
            a = np.asarray(arrays.get(key), dtype=float)
        except (TypeError, ValueError):
            raise SkillError(where, key, "expected a numeric array") from None
        if a.ndim != 2 or a.shape[1] != cols:
            raise SkillError(where, key, f"expected shape (n, {cols}), got {a.shape}")
        if not np.all(np.isfinite(a)):
            row = int(np.argwhere(~np.isfinite(a))[0, 0])
            raise SkillError(where, f"{key}[{row}]", "not finite")
        return a

    if not isinstance(fields_doc, list) or not fields_doc:
        raise SkillError(where, "fields", "expected a non-empty list of fields")
    fields = tuple(Field.from_yaml(f, f"fields[{i}]", where) for i, f in enumerate(fields_doc))
    points = array("points", 3)
    quats = array("quaternions", 4)
    resp = array("responsibilities", len(fields))
    if not (len(points) == len(quats) == len(resp)) or len(points) == 0:
        raise SkillError(where, "points", "points, quaternions and responsibilities need the "
                         f"same non-zero length, got {len(points)}, {len(quats)}, {len(resp)}")
    norms = np.linalg.norm(quats, axis=1)
    bad = np.flatnonzero(np.abs(norms - 1.0) > 1e-3)
    if len(bad):
        raise SkillError(where, f"quaternions[{bad[0]}]", f"not unit (norm {norms[bad[0]]:.6f})")
    return VectorFieldModel(fields=fields, points=points, quaternions=quats / unit_divisor(norms)[:, None],
                            responsibilities=resp)


def _npz_arrays(data: bytes, where: str) -> tuple[dict[str, Any], Any]:
    """The arrays and the ``fields`` document of a pickle-free .npz model file."""
    try:
        with zipfile.ZipFile(io.BytesIO(data)) as zf:
            size = sum(info.file_size for info in zf.infolist())
        if size > MAX_MODEL_BYTES:
            raise SkillError(where, "", f"model file inflates to {size} bytes (at most {MAX_MODEL_BYTES})")
        with np.load(io.BytesIO(data), allow_pickle=False) as z:
            arrays = {k: z[k] for k in ("points", "quaternions", "responsibilities") if k in z}
            fields_doc = json.loads(str(z["fields"])) if "fields" in z else None
    except SkillError:
        raise
    except RecursionError:
        raise SkillError(where, "fields", "invalid JSON (nested too deeply)") from None
    except Exception as exc:  # zipfile, zlib and numpy raise many unrelated types on bad bytes
        raise SkillError(where, "", f"not a pickle-free npz model file ({type(exc).__name__}: "
                         f"{str(exc)[:200]})") from None
    return arrays, fields_doc


def vector_field_model_to_bytes(model: VectorFieldModel, rel: str) -> bytes:
    """Serialise a model for a ``.json`` or pickle-free ``.npz`` model file."""
    fields = [f.to_yaml() for f in model.fields]
    if rel.endswith(".json"):
        return json.dumps({"fields": fields, "points": model.points.tolist(),
                           "quaternions": model.quaternions.tolist(),
                           "responsibilities": model.responsibilities.tolist()}).encode()
    if rel.endswith(".npz"):
        buf = io.BytesIO()
        np.savez_compressed(buf, fields=np.array(json.dumps(fields)), points=model.points,
                            quaternions=model.quaternions,
                            responsibilities=model.responsibilities)
        return buf.getvalue()
    raise SkillError(rel, "", "model files must be .json or .npz")
