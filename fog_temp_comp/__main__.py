"""``python -m fog_temp_comp`` runs the command-line tool."""

import sys

from fog_temp_comp.tools.cli import main

sys.exit(main())
