//! Run a numeric kernel compiled for the widest vector unit this build
//! may use on the processor at hand.
//!
//! The release build targets baseline x86-64, whose vector unit is SSE2
//! (two `f64` per operation); most processors it runs on also have AVX
//! (four). [`with_avx`] runs a closure inside a function compiled with
//! AVX enabled when the processor has it (checked at run time, once per
//! call: a few nanoseconds), so loops inlined into it are vectorised four
//! wide. Only AVX is enabled, not FMA: the compiler never fuses a multiply
//! and an add (Rust does not permit it without fast-math), and vectorising
//! does not reorder floating-point sums, so the kernel gives the same bits
//! either way. The kernels' tests compare both builds to the bit.

/// `f()`, compiled for AVX where the processor has it. Only code inlined
/// into the AVX function is compiled so: mark the closure and the helpers
/// it calls `#[inline(always)]` (a closure's body is otherwise a function
/// of its own, compiled for the baseline).
#[inline(always)]
pub(crate) fn with_avx<R>(f: impl FnOnce() -> R) -> R {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx") {
        // SAFETY: the processor has AVX, checked just above.
        return unsafe { on_avx(f) };
    }
    f()
}

/// `f()` in a function compiled with AVX.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
fn on_avx<R>(f: impl FnOnce() -> R) -> R {
    f()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_kernel_gives_the_same_bits_with_and_without_avx() {
        let x: Vec<f64> = (0..1001).map(|k| (k as f64 * 0.37).sin() * 1e3).collect();
        let kernel = |x: &[f64]| -> Vec<f64> { x.iter().map(|v| (v * 1.7 + 0.3) / 3.1).collect() };
        let plain = kernel(&x);
        let wide = with_avx(
            #[inline(always)]
            || kernel(&x),
        );
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&plain), bits(&wide));
        assert_eq!(with_avx(|| 7), 7);
    }
}
