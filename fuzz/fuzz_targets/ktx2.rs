//! Fuzz target `ktx2`: see `ibl_fuzz::container`.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    ibl_fuzz::init();
    ibl_fuzz::container("ktx2", data)
});
