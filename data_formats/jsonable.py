"""Plain-JSON form of the nested dicts, lists, numpy arrays and scalars our ``describe`` functions return."""

import math

import numpy as np


def jsonable(v):
    """Dicts (string keys), lists, Python scalars; numpy values converted; non-finite floats become None."""
    if isinstance(v, dict):
        return {str(k): jsonable(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [jsonable(x) for x in v]
    if isinstance(v, np.ndarray):
        return jsonable(v.tolist())
    if isinstance(v, np.generic):
        return jsonable(v.item())
    if isinstance(v, float) and not math.isfinite(v):
        return None
    return v
