//! What the trainer's benchmark examples share (a directory module: Cargo does not take it for
//! an example of its own).

/// The value after `name` in `args`, parsed; `default` when the flag is absent or unparsable.
pub fn arg<T: std::str::FromStr>(args: &[String], name: &str, default: T) -> T {
    args.iter()
        .position(|a| a == name)
        .and_then(|i| args.get(i + 1))
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}
