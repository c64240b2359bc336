#!/usr/bin/env bash
# Rewrites the README's sample outputs (blocks marked `<!-- sample: NAME -->`) with what the
# binary prints now; tests/readme.rs checks they still match. Run after changing an output.
set -euo pipefail
cd "$(dirname "$0")/.."
EDMD_UPDATE_README=1 cargo test --test readme -- --nocapture
