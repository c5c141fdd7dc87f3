//! Links the system's libjxl (BSD-3; Debian: `apt-get install libjxl-dev`), the one C library
//! this crate binds. pkg-config finds it where it is installed under another prefix; without
//! pkg-config the linker's default paths are searched.

use std::process::Command;

fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rerun-if-env-changed=PKG_CONFIG_PATH");
    // No libjxl in the browser: the web side hands JPEG XL to the browser's own decoder.
    if std::env::var("CARGO_CFG_TARGET_ARCH").as_deref() == Ok("wasm32") {
        return;
    }
    match Command::new("pkg-config").args(["--libs-only-L", "libjxl"]).output() {
        Ok(out) if out.status.success() => {
            for dir in String::from_utf8_lossy(&out.stdout).split_whitespace() {
                if let Some(dir) = dir.strip_prefix("-L") {
                    println!("cargo:rustc-link-search=native={dir}");
                }
            }
        }
        _ => println!(
            "cargo:warning=pkg-config does not know libjxl: linking -ljxl from the default paths (install libjxl-dev if the link fails)"
        ),
    }
    println!("cargo:rustc-link-lib=dylib=jxl");
}
