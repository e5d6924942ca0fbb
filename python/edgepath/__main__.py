"""`python -m edgepath ...` is the `edgepath` command."""
import sys

from .cli import main

sys.exit(main())
