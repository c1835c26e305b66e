"""The raw tensor files the C++ model tests read back (src/testing/testing.h ReadRawFloats / ReadRawBytes):
little-endian values in `path`, the shape in `path`.json as {"shape": [...]}."""
import json

import numpy as np


def write_raw(path, values, dtype="<f4"):
    """`values`: a torch tensor or a numpy array; stored as `dtype` (float32 by default, "u1" for bytes)."""
    array = values.detach().contiguous().cpu().numpy() if hasattr(values, "detach") else np.asarray(values)
    with open(path, "wb") as f:
        f.write(np.ascontiguousarray(array).astype(dtype).tobytes())
    with open(path + ".json", "w") as f:
        json.dump({"shape": list(array.shape)}, f)
