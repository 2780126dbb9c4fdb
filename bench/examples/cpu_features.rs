//! Prints the SIMD features the standard library detects at run time, one per line, as
//! `name yes|no`. `.ci/verify-emulated-cpu` runs it under the emulator to show that the
//! emulated CPU really hides AVX and FMA from run-time dispatch.

fn main() {
    #[cfg(target_arch = "x86_64")]
    {
        let yes = |b: bool| if b { "yes" } else { "no" };
        println!(
            "sse4.2 {}",
            yes(std::arch::is_x86_feature_detected!("sse4.2"))
        );
        println!("avx {}", yes(std::arch::is_x86_feature_detected!("avx")));
        println!("avx2 {}", yes(std::arch::is_x86_feature_detected!("avx2")));
        println!("fma {}", yes(std::arch::is_x86_feature_detected!("fma")));
        println!(
            "avx512f {}",
            yes(std::arch::is_x86_feature_detected!("avx512f"))
        );
    }
}
