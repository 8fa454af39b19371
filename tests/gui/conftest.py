import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
# tests/support: what every suite shares (waiting.wait_until, docs/testing.md).
sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "support"))
