//! Builds the C++ shim over ur_rtde and links ur_rtde, only when the `ur-rtde` feature is on.
//! The default build compiles nothing here and needs no C++ toolchain or ur_rtde.
//!
//! `UR_RTDE_PREFIX` (default /opt/ur_rtde-1.6.5, as `scripts/install-ur-rtde.sh` installs it)
//! must hold include/ur_rtde/*.h and the static, position-independent lib/librtde.a.

fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    #[cfg(feature = "ur-rtde")]
    ur_rtde::build();
}

#[cfg(feature = "ur-rtde")]
mod ur_rtde {
    use std::path::PathBuf;

    pub(crate) fn build() {
        println!("cargo:rerun-if-env-changed=UR_RTDE_PREFIX");
        println!("cargo:rerun-if-changed=src/ur/shim.cpp");
        println!("cargo:rerun-if-changed=src/ur/shim.h");
        let prefix = PathBuf::from(
            std::env::var("UR_RTDE_PREFIX").unwrap_or_else(|_| "/opt/ur_rtde-1.6.5".to_string()),
        );
        let include = prefix.join("include");
        let lib = prefix.join("lib");
        if !lib.join("librtde.a").exists() || !include.join("ur_rtde").exists() {
            panic!(
                "the ur-rtde feature needs ur_rtde 1.6.5 in {} (lib/librtde.a and include/ur_rtde); \
                 run scripts/install-ur-rtde.sh or set UR_RTDE_PREFIX",
                prefix.display()
            );
        }
        cc::Build::new()
            .cpp(true)
            .std("c++14")
            .file("src/ur/shim.cpp")
            .include(&include)
            // ur_rtde's headers trip these; they are not ours to fix.
            .flag_if_supported("-Wno-unused-parameter")
            .compile("urrtde_shim");
        // Static ur_rtde, then what it needs at run time, in link order.
        println!("cargo:rustc-link-search=native={}", lib.display());
        println!("cargo:rustc-link-lib=static=rtde");
        println!("cargo:rustc-link-lib=dylib=boost_thread");
        println!("cargo:rustc-link-lib=dylib=stdc++");
        println!("cargo:rustc-link-lib=dylib=pthread");
    }
}
