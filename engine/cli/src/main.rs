use std::process::ExitCode;

/// Counts heap bytes for `engine bench` (sph_alloc::CountingAlloc).
#[global_allocator]
static ALLOC: engine::bench::CountingAlloc = engine::bench::CountingAlloc;

/// Runs the 2D or the 3D build, as the scenario asks (`engine::dimensions_asked`).
fn main() -> ExitCode {
    if engine::dimensions_asked(std::env::args_os()) == 3 {
        engine3d::main_with(sph_stages3d::standard_registry())
    } else {
        engine::main_with(sph_stages::standard_registry())
    }
}
