use std::process::ExitCode;

fn main() -> ExitCode {
    engine::main_with(sph_stages::standard_registry())
}
