//! Fuzz target `dds`: the DDS reader (see `ibl_fuzz::container`).
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    ibl_fuzz::init();
    ibl_fuzz::container("dds", data)
});
