// Copies for measuring the memory-bandwidth roofline (dynatex.benchmark.copy_bandwidth).
//
// copy_plain: one float16 per work-item, plain stores.
// copy_stream: BLOCKS (a define) float16 per work-item, stored with streaming (non-temporal) stores
// where the compiler has them. On a CPU a plain store first reads the line it fills, so a
// plain copy moves three bytes for every two it is credited with and understates the
// bandwidth; the streaming copy shows what a copy can reach (and what the players' streaming
// stores are measured against). Without the builtin it is a plain copy in blocks.

__kernel void copy_plain(__global const float16 *restrict a, __global float16 *restrict b)
{
    const size_t i = get_global_id(0);
    b[i] = a[i];
}

#if defined(__clang__) && defined(__has_builtin)
#if __has_builtin(__builtin_nontemporal_store)
#define STREAM_STORE(v, p) __builtin_nontemporal_store((v), (p))
#endif
#endif
#ifndef STREAM_STORE
#define STREAM_STORE(v, p) (*(p) = (v))
#endif

__kernel void copy_stream(__global const float16 *restrict a, __global float16 *restrict b)
{
    const size_t i0 = get_global_id(0) * BLOCKS;
    for (int k = 0; k < BLOCKS; ++k)
        STREAM_STORE(a[i0 + k], b + i0 + k);
#if defined(__x86_64__) || defined(__i386__)
    __builtin_ia32_sfence();       // the streaming stores land before the kernel is seen done
#endif
}
