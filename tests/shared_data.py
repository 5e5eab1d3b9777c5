"""Where the tests find the team's shared folder (the paper, the golden outputs, the real clips'
labels): ``$ASNN_SHARED`` if set, else ``../shared`` beside the repository. The tests that read
it skip where it is absent."""

import os
from pathlib import Path

SHARED = Path(os.environ.get("ASNN_SHARED") or Path(__file__).resolve().parents[2] / "shared")
