import os
import sys

# tests/support: what every suite shares (waiting.wait_until, docs/testing.md).
SUPPORT = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "support")
if SUPPORT not in sys.path:
    sys.path.insert(0, SUPPORT)
