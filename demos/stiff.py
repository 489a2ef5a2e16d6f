"""Demo 'stiff': python demos/stiff.py [stiff.mp4]  (the same as: tianim demo stiff --out stiff.mp4)

The scene itself lives in tianim/gallery/stiff.py, which reads top to bottom.
"""

import sys

from tianim.gallery import load
from tianim.render import export

out = sys.argv[1] if len(sys.argv) > 1 else "stiff.mp4"
demo = load("stiff")
result = export(demo.frames(640, 480, demo.FRAMES, 24.0), out, fps=24.0, total=demo.FRAMES)
print(f"wrote {out}: {result.frames} frames, {result.bytes / 1e6:.2f} MB")
