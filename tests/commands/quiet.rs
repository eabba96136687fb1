//! Commands that open the GPU print nothing harmless on stderr, so real errors stand out: on a
//! headless host without `XDG_RUNTIME_DIR`, `segsplat adapters` used to print libwayland's
//! `XDG_RUNTIME_DIR is invalid or not set` twice (Mesa's device-select layer probing a display).

use crate::segsplat_bin;

#[test]
fn listing_adapters_headless_prints_no_display_noise() {
    let output = std::process::Command::new(segsplat_bin::segsplat_bin())
        .arg("adapters")
        .env_remove("XDG_RUNTIME_DIR")
        .env_remove("NODEVICE_SELECT")
        .env_remove("WAYLAND_DISPLAY")
        .env_remove("DISPLAY")
        .output()
        .expect("running segsplat adapters");
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(output.status.success(), "{stderr}");
    assert!(!stderr.contains("XDG_RUNTIME_DIR"), "{stderr}");
    let adapters: serde_json::Value =
        serde_json::from_slice(&output.stdout).expect("adapters as JSON");
    assert!(adapters.is_array(), "{adapters}");
}
