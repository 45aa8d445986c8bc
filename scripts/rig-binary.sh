# Sourced by the scripts that run `rig`:
#   here  the clone's root
#   rig   the rig binary (RIG, else the release build in CARGO_TARGET_DIR or target/, built if
#         missing)
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
rig="${RIG:-${CARGO_TARGET_DIR:-$here/target}/release/rig}"
[ -x "$rig" ] || (cd "$here" && cargo build --release -p rig >&2)
