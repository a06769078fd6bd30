//! Compiles the firmware's protocol engine (hw/firmware/proto.c) for the `led_firmware`
//! target, instrumented like the Rust code: coverage for libFuzzer, and AddressSanitizer
//! when the build uses it. The platform functions (hal_*) are in the target itself.
fn main() {
    let firmware = "../hw/firmware";
    println!("cargo:rerun-if-changed={firmware}/proto.c");
    println!("cargo:rerun-if-changed={firmware}/proto.h");
    println!("cargo:rerun-if-changed={firmware}/protocol.h");
    let mut build = cc::Build::new();
    build.file(format!("{firmware}/proto.c")).include(firmware).std("c99").define("HW_NAME", "\"fuzz\"").warnings(false);
    build.flag_if_supported("-fsanitize=fuzzer-no-link");
    let sanitizers = std::env::var("CARGO_CFG_SANITIZE").unwrap_or_default();
    if sanitizers.contains("address") {
        build.flag("-fsanitize=address");
    }
    build.compile("rollcam_led_proto");
}
