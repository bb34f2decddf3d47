#!/usr/bin/env bash
# Print the path of a CPython 3.12 interpreter (the only one ROS 2 Jazzy's PyPI wheels support).
# Override with SSI_BRIDGE_PYTHON=/path/to/python3.12. Exits 1 naming every place it looked.
set -u
is_312() { "$1" -c 'import sys; sys.exit(0 if sys.version_info[:2] == (3, 12) else 1)' >/dev/null 2>&1; }

if [ -n "${SSI_BRIDGE_PYTHON:-}" ]; then
  if is_312 "$SSI_BRIDGE_PYTHON"; then echo "$SSI_BRIDGE_PYTHON"; exit 0; fi
  echo "error: SSI_BRIDGE_PYTHON=$SSI_BRIDGE_PYTHON is not a working CPython 3.12" >&2
  exit 1
fi

candidates=(python3.12 python3 /usr/bin/python3.12 /usr/bin/python3 /usr/local/bin/python3.12)
for dir in "${PYENV_ROOT:-$HOME/.pyenv}"/versions/3.12*/bin /root/.pyenv/versions/3.12*/bin; do
  [ -x "$dir/python3.12" ] && candidates+=("$dir/python3.12")
done
for c in "${candidates[@]}"; do
  path=$(command -v "$c" 2>/dev/null) || continue
  if is_312 "$path"; then echo "$path"; exit 0; fi
done
{
  echo "error: no CPython 3.12 found (ROS 2 Jazzy wheels on PyPI are built for 3.12 only)."
  echo "looked for: ${candidates[*]}"
  echo "install python3.12 (Ubuntu 24.04: it is python3) or set SSI_BRIDGE_PYTHON=/path/to/python3.12"
} >&2
exit 1
