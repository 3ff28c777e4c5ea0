//! The `bsdfit` command line; see [`bsdfit::cli`].

fn main() {
    std::process::exit(bsdfit::cli::main());
}
