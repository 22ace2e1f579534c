fn main() -> std::process::ExitCode {
    host_compiler::cli::main()
}
