"""``python -m fog_temp_comp`` runs the command-line tool."""

import sys

try:
    from fog_temp_comp.tools.cli import main
except KeyboardInterrupt:  # Ctrl-C during the imports: nothing started, nothing written
    print('interrupted: nothing written (during start-up)', file=sys.stderr)
    sys.exit(130)

sys.exit(main())
