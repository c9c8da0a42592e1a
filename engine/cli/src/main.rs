use std::process::ExitCode;

/// Counts heap bytes for `engine bench` (engine::bench::CountingAlloc).
#[global_allocator]
static ALLOC: engine::bench::CountingAlloc = engine::bench::CountingAlloc;

fn main() -> ExitCode {
    engine::main_with(sph_stages::standard_registry())
}
