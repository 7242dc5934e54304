"""Test set-up: make the shared factories (tests/factories.py) importable from every folder."""

import os
import sys

sys.path.insert(0, os.path.dirname(__file__))
