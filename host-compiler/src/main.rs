fn main() -> miette::Result<()> {
    host_compiler::cli::main()
}
