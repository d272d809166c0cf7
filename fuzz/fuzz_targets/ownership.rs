//! Fuzz target `ownership`: see `ibl_fuzz::ownership`.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    ibl_fuzz::init();
    ibl_fuzz::ownership(data)
});
