# Sourced by kill-loop.sh and soak.sh: the release binary and the Python
# (with the `mcap` package) they drive, and a check that both are there.
# Set $root and $script_name before sourcing; --bin and --python override.
bin="$root/target/release/motorbench"
python="python3"

# Exit 2 with a message when the binary is missing, or (`require_tools
# mcap`) Python's mcap package.
require_tools() {
    [ -x "$bin" ] || { echo "$script_name: no binary at $bin (cargo build --release --locked)" >&2; exit 2; }
    [ "${1:-}" != mcap ] || "$python" -c 'import mcap' 2>/dev/null ||
        { echo "$script_name: $python lacks the mcap package" >&2; exit 2; }
}
