"""``python -m umbrella_sim``: the offline command line (simulate, sweep)."""
import sys

from .tools.entry import cli_main

sys.exit(cli_main())
