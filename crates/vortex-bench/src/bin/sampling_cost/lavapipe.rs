//! Which Vulkan driver runs the measurement: lavapipe (Mesa's CPU driver) when it is installed
//! and no driver was chosen, as in the tests, so that the numbers are comparable across runs.

use std::path::Path;

const LAVAPIPE_ICD: &str = "/usr/share/vulkan/icd.d/lvp_icd.x86_64.json";

/// Points the Vulkan loader at lavapipe, as the tests do, unless a driver is already chosen.
pub fn pin() {
    // SAFETY: called in `main` before any other thread exists (the loaders' workers
    // and the drivers' threads are started later), so nothing reads the environment meanwhile.
    unsafe {
        if std::env::var_os("VK_DRIVER_FILES").is_none()
            && std::env::var_os("VK_ICD_FILENAMES").is_none()
            && Path::new(LAVAPIPE_ICD).exists()
        {
            std::env::set_var("VK_DRIVER_FILES", LAVAPIPE_ICD);
        }
        if std::env::var_os("NODEVICE_SELECT").is_none() {
            std::env::set_var("NODEVICE_SELECT", "1");
        }
    }
}
