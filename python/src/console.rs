//! The `bsdfit` command of the Python package: the command line run whole, through the
//! native module (the one place the module uses `bsdfit::cli`), so `pip install` gives
//! the same command as `cargo build` with no second build.

use super::*;

/// Run the command line `args` (the program's name first); its exit code. The GIL is
/// released while it runs; a panic becomes a RuntimeError, as in every native call.
#[pyfunction]
pub(crate) fn run_cli(py: Python<'_>, args: Vec<String>) -> PyResult<i32> {
    let outcome =
        py.detach(|| catch_unwind(AssertUnwindSafe(|| Ok(bsdfit::cli::main_with_args(args)))));
    caught(outcome)
}
