//! Fuzz target `zstd`: the KTX2 reader on zstd-supercompressed files (see `ibl_fuzz::container`).
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    ibl_fuzz::init();
    ibl_fuzz::container("zstd", data)
});
