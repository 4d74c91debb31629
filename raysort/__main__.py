"""``python -m raysort`` runs the command line."""
import sys

from raysort.cli import main

sys.exit(main())
