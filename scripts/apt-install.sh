#!/usr/bin/env bash
# Installs the Debian packages named on the command line that are not installed yet: as root
# directly, otherwise through `sudo` when it needs no password; otherwise it names them and the
# command to run, and fails. Waits up to 10 minutes for another apt/dpkg to release its lock
# instead of failing at once.
set -euo pipefail
missing=()
for p in "$@"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
[ ${#missing[@]} -eq 0 ] && exit 0
if [ "$(id -u)" -eq 0 ]; then
  as_root=()
elif command -v sudo >/dev/null && sudo -n true 2>/dev/null; then
  as_root=(sudo -n)
else
  echo "apt-install: missing Debian packages: ${missing[*]}" >&2
  echo "apt-install: install them (sudo apt-get install ${missing[*]}) or run this as root" >&2
  exit 1
fi
echo "apt-install: installing ${missing[*]}"
lock=(-o DPkg::Lock::Timeout=600)
"${as_root[@]}" apt-get "${lock[@]}" update -q
"${as_root[@]}" env DEBIAN_FRONTEND=noninteractive \
  apt-get "${lock[@]}" install -y -q --no-install-recommends "${missing[@]}"
