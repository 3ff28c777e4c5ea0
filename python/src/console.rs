//! The `bsdfit` command of the Python package: the command line run whole, through the
//! native module (the one place the module uses `bsdfit::cli`), so `pip install` gives
//! the same command as `cargo build` with no second build.

use super::*;

/// Run the command line `args` (the program's name first); its exit code. The GIL is
/// released while it runs; a panic becomes a RuntimeError.
#[pyfunction]
pub(crate) fn run_cli(py: Python<'_>, args: Vec<String>) -> PyResult<i32> {
    let outcome =
        py.detach(|| catch_unwind(AssertUnwindSafe(|| bsdfit::cli::main_with_args(args))));
    outcome.map_err(|p| {
        let text = p
            .downcast_ref::<String>()
            .map(String::as_str)
            .or_else(|| p.downcast_ref::<&str>().copied())
            .unwrap_or("a panic");
        PyRuntimeError::new_err(format!("internal error in bsdfit: {text}"))
    })
}
