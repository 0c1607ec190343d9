"""Held-out scenes for `examples/noise_budget_probe.rs` (EXTRA_DIR): scikit-image's
bundled data images as 8-bit RGB PNGs (grey ones as three equal channels). Nothing is
fitted on them; BENCHMARKS.md "The blind noise's texture floor" reads them.

    python3 -m venv /tmp/pv && /tmp/pv/bin/pip install scikit-image pillow
    /tmp/pv/bin/python benches/noise_scenes/make.py /tmp/heldout
    EXTRA_DIR=/tmp/heldout BUDGETS=10000 DETAIL=1 cargo run --release --example noise_budget_probe

Measured with scikit-image 0.26.0.
"""
import pathlib, sys
import numpy as np
import skimage.data
from PIL import Image

NATURAL = ["camera", "clock", "coffee", "coins", "moon", "retina", "rocket"]
TEXTURES = ["brick", "grass", "gravel", "immunohistochemistry"]
OTHER = ["hubble_deep_field"]

out = pathlib.Path(sys.argv[1] if len(sys.argv) > 1 else "/tmp/heldout")
out.mkdir(parents=True, exist_ok=True)
for name in NATURAL + TEXTURES + OTHER:
    im = getattr(skimage.data, name)()
    assert im.dtype == np.uint8, (name, im.dtype)
    if im.ndim == 2:
        im = np.stack([im] * 3, -1)
    Image.fromarray(im[..., :3]).save(out / f"{name}.png")
    print(name, im.shape)
