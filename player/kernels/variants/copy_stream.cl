// Variant for the benchmark's bandwidth measurement only (dynatex.benchmark.copy_bandwidth):
// BLOCKS (a define) float16 per work-item, stored with clang's streaming (non-temporal)
// stores and fenced on x86. Not portable OpenCL C; the benchmark skips it where it does not
// build, and no player uses it.

__kernel void copy_stream(__global const float16 *restrict a, __global float16 *restrict b)
{
    const size_t i0 = get_global_id(0) * BLOCKS;
    for (int k = 0; k < BLOCKS; ++k)
        __builtin_nontemporal_store(a[i0 + k], b + i0 + k);
#if defined(__x86_64__) || defined(__i386__)
    __builtin_ia32_sfence();       // the streaming stores land before the kernel is seen done
#endif
}
