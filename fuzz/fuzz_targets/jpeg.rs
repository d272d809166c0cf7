//! Fuzz target `jpeg`: see `ibl_fuzz::jpeg`.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    ibl_fuzz::init();
    ibl_fuzz::jpeg(data)
});
