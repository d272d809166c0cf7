//! Fuzz target `ktx2`: see `ibl_fuzz::ktx2`.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    ibl_fuzz::init();
    ibl_fuzz::ktx2(data)
});
