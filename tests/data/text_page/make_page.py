"""Renders tests/data/text_page/page.png: a 640×480 page of printed-looking text
(DejaVu Sans 18 px, Debian's fonts-dejavu-core, dark ink on light paper, lines
1.5 em apart, a 0.6 px Gaussian optical blur). Texture with a letter pitch across
its lines and a line pitch along them, for the blind motion-blur tests
(tests/fast_path.rs). Run: python3 make_page.py (Pillow, NumPy, OpenCV); the PNG
in the repository is the fixture — FreeType versions may rasterise differently.
"""
import random
from pathlib import Path

import cv2
import numpy as np
from PIL import Image, ImageDraw, ImageFont

WORDS = ("the of probability distribution marginal computed as and camera blur noise model "
         "frame estimate which is a to in that with for each pixel image motion").split()


def page(seed=2, w=640, h=480, size=18, font="/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf"):
    rnd = random.Random(seed)
    im = Image.new("L", (w, h), 225)
    d = ImageDraw.Draw(im)
    f = ImageFont.truetype(font, size)
    y = 5
    while y < h - size:
        x = 5 + rnd.randint(0, 20)
        line = ""
        while True:
            wd = rnd.choice(WORDS)
            if d.textlength(line + wd + " ", font=f) > w - 10:
                break
            line += wd + " "
        d.text((x, y), line, fill=30, font=f)
        y += int(size * 1.5) + rnd.randint(0, 2)
    a = cv2.GaussianBlur(np.asarray(im).astype(np.float32), (0, 0), 0.6)
    return a.clip(0, 255).astype(np.uint8)


if __name__ == "__main__":
    Image.fromarray(page()).save(Path(__file__).with_name("page.png"))
