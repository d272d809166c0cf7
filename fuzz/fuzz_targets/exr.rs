//! Fuzz target `exr`: see `ibl_fuzz::exr`.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    ibl_fuzz::init();
    ibl_fuzz::exr(data)
});
