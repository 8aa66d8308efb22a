"""What a registered planner version is to the method its reference describes.

"original": the method as its authors published it (paper, and their public code where it
exists), differing only where the framework forces it (`docs/planners.md`) or where the sources
are silent and a choice had to be made; these are the rows to set beside the paper's.
"variant": it differs beyond that (an addition of ours, or a difference a later version
removes). "" (uploaded or third-party planners that do not say): not stated.
"""

from __future__ import annotations

ORIGINAL, VARIANT, UNSTATED = "original", "variant", ""
METHODS = (ORIGINAL, VARIANT, UNSTATED)
