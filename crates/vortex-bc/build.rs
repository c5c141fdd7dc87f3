//! intel_tex_2's prebuilt kernels contain C++ code that needs the C++ runtime, which that crate
//! does not link itself. Linked here, once, for every crate that encodes BC blocks.

fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    // In the browser there are no kernels (and no C++ runtime to link): see the crate's docs.
    if std::env::var("CARGO_CFG_TARGET_ARCH").as_deref() == Ok("wasm32") {
        return;
    }
    match std::env::var("CARGO_CFG_TARGET_OS").as_deref() {
        Ok("macos" | "ios") => println!("cargo:rustc-link-lib=dylib=c++"),
        Ok("windows") => {}
        _ => println!("cargo:rustc-link-lib=dylib=stdc++"),
    }
}
