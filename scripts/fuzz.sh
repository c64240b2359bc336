#!/usr/bin/env bash
# Fuzzes edmd's three front doors (G-code parser, configuration loader, control protocol)
# with cargo-fuzz / libFuzzer, one target after the other.
#
#   scripts/fuzz.sh [SECONDS_PER_TARGET] [TARGET...]      (defaults: 600, all three)
#
# Needs a nightly toolchain and cargo-fuzz (`rustup toolchain install nightly`,
# `cargo install cargo-fuzz`). The growing corpus lives in fuzz/corpus/<target> (not committed);
# the committed seeds in fuzz/seeds/<target> are read as a second corpus. A crash is written to
# fuzz/artifacts/<target>/; copy it to fuzz/regressions/<target>/ once fixed, and
# `cargo test --test it fuzz_regressions::` replays it on stable Rust from then on.
set -euo pipefail
cd "$(dirname "$0")/../fuzz"
seconds=${1:-600}
shift || true
targets=("$@")
[ ${#targets[@]} -gt 0 ] || targets=(gcode config protocol)
status=0
for t in "${targets[@]}"; do
  mkdir -p "corpus/$t"
  echo "== $t: ${seconds} s"
  if ! cargo +nightly fuzz run "$t" "corpus/$t" "seeds/$t" -- \
      -max_total_time="$seconds" -timeout=5 -rss_limit_mb=2048 -print_final_stats=1; then
    echo "== $t: CRASH, see fuzz/artifacts/$t/" >&2
    status=1
  fi
done
exit $status
