"""Make this folder's helpers (verify_models.py) importable under --import-mode=importlib."""

import os
import sys

sys.path.insert(0, os.path.dirname(__file__))
