#!/usr/bin/env bash
# Builds the Debian package from a staged tree with dpkg-deb: the binary (stripped), its man
# pages and shell completions (made by the binary from its own command-line definition), the
# unit, the sysusers, tmpfiles and modules-load snippets, /etc/edmd/edmd.toml and the example
# technology tables (/etc/edmd/technology/) as conffiles,
# and the maintainer scripts in systemd/deb/. Prints the package's path.
#
#   scripts/deb.sh                 # builds the release binary (fat LTO) and packs it
#   scripts/deb.sh target/debug/edmd   # packs a binary already built (CI packs the one it
#                                      # tested: no second build)
#
# Needs dpkg-deb, objdump and strip (Debian's dpkg and binutils); nothing from crates.io.
set -euo pipefail
cd "$(dirname "$0")/.."
if [ $# -ge 1 ]; then
  bin="$1"
else
  cargo build --release --locked --quiet
  bin=target/release/edmd
fi
[ -x "$bin" ] || { echo "deb.sh: $bin is not an executable" >&2; exit 1; }

version="$(sed -n 's/^version = "\(.*\)"/\1/p' Cargo.toml | head -n 1)"
arch="$(dpkg --print-architecture)"
stage=target/debian/stage
rm -rf "$stage"
mkdir -p "$stage/DEBIAN" "$stage/usr/bin" "$stage/etc/edmd" "$stage/usr/share/doc/edmd" \
  "$stage/usr/share/man/man1" "$stage/usr/lib/systemd/system" "$stage/usr/lib/sysusers.d" \
  "$stage/usr/lib/tmpfiles.d" "$stage/usr/lib/modules-load.d" \
  "$stage/usr/share/bash-completion/completions" "$stage/usr/share/zsh/vendor-completions" \
  "$stage/usr/share/fish/vendor_completions.d"

install -m 755 "$bin" "$stage/usr/bin/edmd"
strip --strip-unneeded "$stage/usr/bin/edmd"
install -m 644 config/edmd.toml "$stage/etc/edmd/edmd.toml"
# The example technology tables (example = true): the machine builder replaces them.
install -d "$stage/etc/edmd/technology"
install -m 644 config/technology/*.toml "$stage/etc/edmd/technology/"
install -m 644 systemd/edmd.service "$stage/usr/lib/systemd/system/edmd.service"
install -m 644 systemd/edmd-hal.service "$stage/usr/lib/systemd/system/edmd-hal.service"
install -m 644 systemd/edmd-sysusers.conf "$stage/usr/lib/sysusers.d/edmd.conf"
install -m 644 systemd/edmd-tmpfiles.conf "$stage/usr/lib/tmpfiles.d/edmd.conf"
install -m 644 systemd/edmd-modules.conf "$stage/usr/lib/modules-load.d/edmd.conf"
install -m 644 README.md "$stage/usr/share/doc/edmd/README.md"
install -d "$stage/usr/share/doc/edmd/docs"
install -m 644 docs/*.md docs/*.png "$stage/usr/share/doc/edmd/docs/"
# HAL files: the simulated machine and the examples to adapt (docs/hal.md).
install -d "$stage/usr/share/doc/edmd/hal"
install -m 644 config/hal/*.hal config/hal/*.toml "$stage/usr/share/doc/edmd/hal/"
{
  echo "Format: https://www.debian.org/doc/packaging-manuals/copyright-format/1.0/"
  echo "Upstream-Name: edmd"
  echo
  echo "Files: *"
  echo "Copyright: 2026, The edmd developers"
  echo "License: MIT or Apache-2.0"
} >"$stage/usr/share/doc/edmd/copyright"
chmod 644 "$stage/usr/share/doc/edmd/copyright"

"$bin" man --out "$stage/usr/share/man/man1" 2>/dev/null
# edmd.toml(5), the configuration's page, goes to section 5.
install -d "$stage/usr/share/man/man5"
mv "$stage/usr/share/man/man1/edmd.toml.5" "$stage/usr/share/man/man5/"
gzip -9n "$stage"/usr/share/man/man1/*.1 "$stage"/usr/share/man/man5/*.5
chmod 644 "$stage"/usr/share/man/man1/*.1.gz "$stage"/usr/share/man/man5/*.5.gz
"$bin" completions bash >"$stage/usr/share/bash-completion/completions/edmd"
"$bin" completions zsh >"$stage/usr/share/zsh/vendor-completions/_edmd"
"$bin" completions fish >"$stage/usr/share/fish/vendor_completions.d/edmd.fish"

# Depends: the packages owning the shared libraries the binary links, glibc at the newest
# symbol version it calls (what dpkg-shlibdeps would find), and systemd for the unit.
glibc="$(objdump -T "$bin" | grep -o 'GLIBC_[0-9.]*' | sed 's/GLIBC_//' | sort -V | tail -n 1)"
depends=()
while read -r lib; do
  pkg="$(dpkg -S "$(realpath "$lib")" 2>/dev/null | head -n 1 | cut -d: -f1)" || true
  [ -n "$pkg" ] || pkg="$(dpkg -S "$lib" 2>/dev/null | head -n 1 | cut -d: -f1)" || true
  [ -n "$pkg" ] || { echo "deb.sh: no package owns $lib" >&2; exit 1; }
  if [ "$pkg" = libc6 ]; then
    depends+=("libc6 (>= $glibc)")
  else
    depends+=("$pkg")
  fi
done < <(ldd "$bin" | awk '$2 == "=>" && $3 ~ /^\// {print $3}')
depends+=(systemd)
depends_line="$(printf '%s\n' "${depends[@]}" | sort -u | paste -sd, | sed 's/,/, /g')"

for script in postinst prerm postrm; do
  install -m 755 "systemd/deb/$script" "$stage/DEBIAN/$script"
done
{
  echo /etc/edmd/edmd.toml
  for table in config/technology/*.toml; do echo "/etc/edmd/technology/${table##*/}"; done
} >"$stage/DEBIAN/conffiles"
size_kib="$(du -sk --exclude=DEBIAN "$stage" | cut -f1)"
cat >"$stage/DEBIAN/control" <<EOF
Package: edmd
Version: $version
Architecture: $arch
Maintainer: The edmd developers <edmd@invalid>
Installed-Size: $size_kib
Depends: $depends_line
Suggests: linuxcnc-uspace
Section: electronics
Priority: optional
Description: Real-time NURBS interpolation daemon for PC-based EDM controllers
 edmd turns G-code (lines, arcs and NURBS, LinuxCNC's and Fanuc's dialects) into step and
 direction pulses for an EDM machine: a producer thread segments the path within a chord
 tolerance and plans the feed; a fixed-period real-time thread interpolates, runs the gap
 servo and turns back along the executed path on a short. It runs as a systemd service
 (Type=notify, watchdog) controlled with edmd ctl and an optional web page.
EOF
(cd "$stage" && find . -path ./DEBIAN -prune -o -type f -printf '%P\0' | sort -z |
  xargs -0 md5sum >DEBIAN/md5sums)
deb="target/debian/edmd_${version}_${arch}.deb"
# xz for the package a user downloads; CI, which installs it once and purges it, asks for
# gzip (DEB_COMPRESSION=gzip): the same files, packed in 2 s instead of 15.
dpkg-deb --root-owner-group -Z"${DEB_COMPRESSION:-xz}" --build "$stage" "$deb" >/dev/null
echo "$deb"
