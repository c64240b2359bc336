#!/usr/bin/env bash
# Builds the Debian package: the release binary, its man pages and shell completions (made by
# the binary from its own command-line definition), then `cargo deb` packs them with the unit
# and the config (Cargo.toml's [package.metadata.deb]). Needs cargo-deb
# (`cargo install cargo-deb --locked`). Prints the package's path.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release --locked --quiet
bin=target/release/edmd
rm -rf target/assets
mkdir -p target/assets/man target/assets/completions
"$bin" man --out target/assets/man 2>/dev/null
gzip -9n target/assets/man/*.1
"$bin" completions bash > target/assets/completions/edmd
"$bin" completions zsh > target/assets/completions/_edmd
"$bin" completions fish > target/assets/completions/edmd.fish
cargo deb --no-build --locked --quiet >/dev/null
ls target/debian/edmd_*.deb | tail -n 1
