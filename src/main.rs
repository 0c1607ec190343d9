//! The desktop binary `blind-augment`: command-line wiring only (see
//! `platform/desktop`); all work happens in the library.

#[path = "platform/desktop/mod.rs"]
mod desktop;

fn main() -> std::process::ExitCode {
    desktop::main()
}
