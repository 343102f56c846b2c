//! The `hbn` binary: see `hbn --help`.

fn main() {
    let code = hbn_cli::main_exit_code(hbn_cli::run(std::env::args_os()));
    std::process::exit(code);
}
