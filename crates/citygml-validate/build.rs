//! Links the system libxml2 (Debian `libxml2-dev`) for in-process XSD validation.
fn main() {
    if let Err(e) = pkg_config::Config::new().atleast_version("2.9").probe("libxml-2.0") {
        // Fall back to the plain library name: Debian puts it on the default linker path.
        println!("cargo:warning=pkg-config could not find libxml-2.0 ({e}); linking -lxml2");
        println!("cargo:rustc-link-lib=xml2");
    }
}
