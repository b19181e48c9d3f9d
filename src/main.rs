//! The `physnap` binary: the command line lives in `cli/`; this file only installs the allocator
//! and hands over.

use std::process::ExitCode;

mod cli;

// mimalloc instead of glibc malloc: the ML stack allocates and frees many short-lived buffers
// per step, and glibc's allocator roughly doubles backward-pass time (ml-stack.md §TL;DR).
#[global_allocator]
static GLOBAL: mimalloc::MiMalloc = mimalloc::MiMalloc;

fn main() -> ExitCode {
    cli::main()
}
