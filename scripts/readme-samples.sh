#!/usr/bin/env bash
# Rewrites the sample outputs of docs/commands.md (blocks marked `<!-- sample: NAME -->`) with what the
# binary prints now; tests/it/readme.rs checks they still match. Run after changing an output.
set -euo pipefail
cd "$(dirname "$0")/.."
EDMD_UPDATE_README=1 cargo test --test it readme -- --nocapture
