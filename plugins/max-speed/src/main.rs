//! The `engine` command with the MaxSpeed plugin stage registered beside the standard
//! ones: `cargo run --release -p max-speed -- plugins/max-speed/max_speed.ron`.

fn main() -> std::process::ExitCode {
    let mut registry = sph_stages::standard_registry();
    max_speed::register(&mut registry);
    engine::main_with(registry)
}
