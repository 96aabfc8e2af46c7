// Copies for measuring the memory-bandwidth roofline (dynatex.benchmark.copy_bandwidth).
//
// copy_plain: one float16 per work-item, plain stores. The benchmark also measures the
// streaming copy of variants/copy_stream.cl where that builds: on a CPU a plain store first
// reads the line it fills, so a plain copy moves three bytes for every two it is credited
// with and understates the bandwidth.

__kernel void copy_plain(__global const float16 *restrict a, __global float16 *restrict b)
{
    const size_t i = get_global_id(0);
    b[i] = a[i];
}
