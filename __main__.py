"""``python -m relray``: the relray command (:func:`relray.cli_main`)."""

import sys

from . import cli_main

sys.exit(cli_main())
