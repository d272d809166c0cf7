//! Fuzz target `png`: see `ibl_fuzz::png`.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    ibl_fuzz::init();
    ibl_fuzz::png(data)
});
