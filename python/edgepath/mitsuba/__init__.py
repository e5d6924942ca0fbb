"""Mitsuba 3 scene files (split by what they load in the next commit)."""

from .loader import *  # noqa: F401,F403
from .loader import UNBOUNDED_MAX_BOUNCES, MitsubaError, MitsubaScene, load_mitsuba  # noqa: F401
