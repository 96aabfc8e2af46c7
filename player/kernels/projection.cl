// Projection: frame = mean + sum_i coef_i * basis[i], written as saturated uint8, for
// `frames` coefficient vectors in one pass over the basis, with the fine detail added in the
// same pass where the model has it (DETAIL).
//
// One work-item owns PIXELS consecutive pixels (GROUP = PIXELS * CHANNELS values). The basis
// is stored blocked for streaming: for group g, its n x GROUP sub-matrix is contiguous (row i
// at offset (g * n + i) * GROUP), so one work-item reads one contiguous run and consecutive
// work-items read consecutive runs. A work-item projects every frame of the pass from that
// run: the first frame brings it into cache (n * GROUP values: a few KiB), the others read it
// from there, so k frames cost about one frame's memory traffic.
//
// DETAIL: out = clamp(round(p + gain * (w0 * vol[layer 0] + w1 * vol[layer 1])), low, high),
// or clamp(p, low, high) where that colour's bin ((r >> 3) * 1024 + (g >> 3) * 32 + (b >> 3))
// is not in the source's colour set (colours[bin] == 0); p is the projected uint8 value, so
// the detail sees the integers a separate pass would. The volume (Tv, VH, VW, CHANNELS) int8
// wraps in y and x, and is stored with each row's first PIXELS - 1 pixels repeated after its
// end (rows of VWP pixels), so that any PIXELS consecutive pixels of a row are one contiguous
// run. Frame f's layers are the last LAYER_FLOATS values of its coefficient row (one upload
// per pass): t0, oy0, ox0, t1, oy1, ox1 (small integers, exact as floats), w0, w1; layer k
// reads volume frame tk at offset (oyk, oxk) with weight wk. gain holds one value per pixel
// (spread over a pixel's channels with shuffles).
// Contraction is off there so that the result equals the numpy reference bit for bit.
//
// TONE: the model was learned on tone values (the `tone` part): each sum y of channel c becomes
// the level table[c * TONE_BINS + b], b = (int)clamp((y - lo[c]) * scale[c], 0, TONE_BINS - 1)
// (tone holds lo[0..CHANNELS-1], then scale[0..CHANNELS-1]), instead of the sum rounded and
// saturated; contraction is off so that b equals the numpy reference's for the same y.
//
// GAMUT (CHANNELS 3 only): last, a pixel whose colour bin is not its own nearest[bin] (the
// nearest bin of the source's colour set) is clamped into that bin, channel by channel
// (integers alone: exact).
//
// LOCAL (with GAMUT): instead, each pixel moves into the colour sets of its four nearest regions
// (squares of LOCAL_BLOCK pixels, LOCAL_ROWS x LOCAL_COLS), blended: for each region, the pixel
// as it is where the region holds its bin, else clamped into the bin the region's map names for
// its 16-level cell (cell = (r >> 4) * 256 + (g >> 4) * 16 + (b >> 4)): one lookup,
// e = local_sets[region * 4096 + cell], bits 0..14 that bin, bit 16 + k set where the region
// holds the cell's k-th bin (k = ((r >> 3) & 1) * 4 + ((g >> 3) & 1) * 2 + ((b >> 3) & 1)); the
// four colours weighted by the pixel's position between the regions' centres (per axis an
// integer out of 2^LOCAL_WEIGHT_BITS, the four products summing to 2^(2 LOCAL_WEIGHT_BITS)),
// rounded by a shift: integers alone, exact. A
// colour all four hold stays: the four regions around each corner where region centres meet (a
// quad, (LOCAL_ROWS + 1) x (LOCAL_COLS + 1), clamped at the frame's edges) have their bins all
// four hold at local_quads[quad * 8192 + (bin >> 3)], bit bin & 7, so that this costs one
// lookup, and those one of the four holds at local_quads[quad * 8192 + 4096 + (bin >> 3)]: a
// blend that fell in none of the four sets is blended again (up to LOCAL_PASSES passes); a
// blend, last, clamped into its nearest[bin] of the clip's set like GAMUT's (a blend of colours
// from different regions can lie outside the clip's set, which holds each region's).
//
// Defines: HALF (1: basis stored as half floats), CHANNELS (1 or 3: values per pixel of the
// basis; grey is replicated), PIXEL_BYTES (3 or 4: bytes per output pixel), R_AT, G_AT, B_AT
// (the byte of each colour in an output pixel), A_AT (alpha's, 255; -1: none), TONE (0 or 1) and
// TONE_BINS, DETAIL (0 or 1), VH and VW (the detail volume's rows and columns; constants, so that the wrap is cheap),
// GAMUT (0 or 1), LOCAL (0 or 1), LOCAL_BLOCK, LOCAL_ROWS, LOCAL_COLS, LOCAL_WEIGHT_BITS and LOCAL_PASSES.

#define PIXELS 16
#define GROUP (PIXELS * CHANNELS)
#define VWP (VW + PIXELS - 1)
#define LAYER_FLOATS 8

#if HALF
typedef half basis_t;
#define LOAD(row, j) vload_half16(j, row)
#else
typedef float basis_t;
#define LOAD(row, j) vload16(j, row)
#endif

#if CHANNELS == 3
#define BIN(d, i) ((((d)[i] >> 3) << 10) | (((d)[(i) + 1] >> 3) << 5) | ((d)[(i) + 2] >> 3))
#else
#define BIN(d, i) ((((d)[i] >> 3) << 10) | (((d)[i] >> 3) << 5) | ((d)[i] >> 3))
#endif

#if TONE
#if CHANNELS == 3
// the channel of each lane of the j-th vector of a group (a group starts at channel 0)
#define LANE_CHANNELS(j)                                                                                    \
    ((j) == 0   ? (uint16)(0, 1, 2, 0, 1, 2, 0, 1, 2, 0, 1, 2, 0, 1, 2, 0)                                  \
     : (j) == 1 ? (uint16)(1, 2, 0, 1, 2, 0, 1, 2, 0, 1, 2, 0, 1, 2, 0, 1)                                  \
                : (uint16)(2, 0, 1, 2, 0, 1, 2, 0, 1, 2, 0, 1, 2, 0, 1, 2))
#else
#define LANE_CHANNELS(j) ((uint16)(0))
#endif

// The 16 tone values y, values 16 j .. 16 j + 15 of a group, as levels into v (the header's TONE).
void to_levels(uchar *v, const float16 y, const int j, __global const float *restrict tone,
               __global const uchar *restrict table)
{
#pragma OPENCL FP_CONTRACT OFF
    const uint16 ch = LANE_CHANNELS(j);
    const float4 lo = (float4)(tone[0], tone[min(1, CHANNELS - 1)], tone[min(2, CHANNELS - 1)], 0.0f);
    const float4 scale = (float4)(tone[CHANNELS], tone[CHANNELS + min(1, CHANNELS - 1)],
                                  tone[CHANNELS + min(2, CHANNELS - 1)], 0.0f);
    const float16 t = clamp((y - shuffle(lo, ch)) * shuffle(scale, ch), 0.0f, (float)(TONE_BINS - 1));
    int b[16];
    vstore16(convert_int16_rtz(t) + convert_int16(ch) * TONE_BINS, 0, b);
    for (int i = 0; i < 16; ++i)
        v[16 * j + i] = table[b[i]];
}
#endif

#if GAMUT
#if CHANNELS != 3
#error "GAMUT needs CHANNELS 3"
#endif
// Pixel p (3 values) clamped, channel by channel, into colour bin t.
void into_bin(uchar *p, const int t)
{
    const int r = (t >> 10) << 3, g = ((t >> 5) & 31) << 3, b = (t & 31) << 3;
    p[0] = (uchar)clamp((int)p[0], r, r + 7);
    p[1] = (uchar)clamp((int)p[1], g, g + 7);
    p[2] = (uchar)clamp((int)p[2], b, b + 7);
}

// The `count` pixels of v moved into the source's colour set (the header's GAMUT).
void snap_colours(uchar *v, const int count, __global const ushort *restrict nearest)
{
    for (int q = 0; q < count; ++q) {
        uchar *p = v + 3 * q;
        const int bin = BIN(p, 0);
        const int t = nearest[bin];
        if (t != bin) {
            into_bin(p, t);
        }
    }
}

#if LOCAL
#define LOCAL_ONE (1 << LOCAL_WEIGHT_BITS)
#define LOCAL_HALF (1 << (2 * LOCAL_WEIGHT_BITS - 1))

// Along an axis of n regions (LOCAL_ROWS or LOCAL_COLS), coordinate u: the quad it lies in
// (0 .. n: between regions quad - 1 and quad, each clamped to 0 .. n - 1) and the upper region's
// weight out of LOCAL_ONE (*w).
int between(const int u, int *w)
{
    const int d = 2 * u + 1 - LOCAL_BLOCK;  // twice the offset from region 0's centre, > -2 LOCAL_BLOCK
    const int i = d < 0 ? -1 : d / (2 * LOCAL_BLOCK);
    *w = (((d - i * 2 * LOCAL_BLOCK) << LOCAL_WEIGHT_BITS) + LOCAL_BLOCK) / (2 * LOCAL_BLOCK);
    return i + 1;
}

// Colour c's bin (c.s0..s2: its levels).
int bin_of(const int4 c)
{
    return ((c.s0 >> 3) << 10) | ((c.s1 >> 3) << 5) | (c.s2 >> 3);
}

// Whether the quad's four regions all hold colour c (quad[0 .. 4095]), or (any) one of them
// does (quad[4096 .. 8191]).
bool quad_holds(const int4 c, __global const uchar *restrict quad, const int any)
{
    const int bin = bin_of(c);
    return ((quad[any * 4096 + (bin >> 3)] >> (bin & 7)) & 1) != 0;
}

// One pass of the blend on colour c over regions reg with weights w (LOCAL). A region that holds
// its colour clamps it into its own bin (no change), so the four are treated alike.
int4 blend_sets(const int4 c, const int4 reg, const int4 w, __global const uint *restrict sets)
{
    const int bin = bin_of(c);
    const int cell = ((c.s0 >> 4) << 8) | ((c.s1 >> 4) << 4) | (c.s2 >> 4);
    const int held = 16 + (((c.s0 >> 1) & 4) | ((c.s1 >> 2) & 2) | ((c.s2 >> 3) & 1));
    const int r[4] = {reg.s0, reg.s1, reg.s2, reg.s3};
    const int wk[4] = {w.s0, w.s1, w.s2, w.s3};
    int s0 = LOCAL_HALF, s1 = LOCAL_HALF, s2 = LOCAL_HALF;
    for (int k = 0; k < 4; ++k) {
        const uint e = sets[r[k] * 4096 + cell];
        const int t = ((e >> held) & 1) ? bin : (int)(e & 0x7FFF);
        const int lr = (t >> 10) << 3, lg = ((t >> 5) & 31) << 3, lb = (t & 31) << 3;
        s0 += wk[k] * clamp(c.s0, lr, lr + 7);
        s1 += wk[k] * clamp(c.s1, lg, lg + 7);
        s2 += wk[k] * clamp(c.s2, lb, lb + 7);
    }
    return (int4)(s0, s1, s2, 0) >> (2 * LOCAL_WEIGHT_BITS);
}

// The `count` pixels of v, the first at (x, y), moved into their four nearest regions' colour
// sets, blended (LOCAL).
void snap_local(uchar *v, const int count, const int x, const int y, const int width,
                __global const uint *restrict sets, __global const uchar *restrict quads,
                __global const ushort *restrict nearest)
{
    int wy, wx;
    int qy = between(y, &wy);
    for (int q = 0, u = x; q < count; ++q, ++u) {
        if (u == width) {
            u = 0;
            qy = between(y + (x + q) / width, &wy);
        }
        const int qx = between(u, &wx);
        __global const uchar *restrict quad = quads + (qy * (LOCAL_COLS + 1) + qx) * 8192;
        uchar *p = v + 3 * q;
        int4 c = (int4)(p[0], p[1], p[2], 0);
        if (quad_holds(c, quad, 0))
            continue;  // all four hold it
        const int ry0 = max(qy - 1, 0) * LOCAL_COLS, ry1 = min(qy, LOCAL_ROWS - 1) * LOCAL_COLS;
        const int rx0 = max(qx - 1, 0), rx1 = min(qx, LOCAL_COLS - 1);
        const int4 reg = (int4)(ry0 + rx0, ry0 + rx1, ry1 + rx0, ry1 + rx1);
        const int4 w = (int4)((LOCAL_ONE - wy) * (LOCAL_ONE - wx), (LOCAL_ONE - wy) * wx,
                              wy * (LOCAL_ONE - wx), wy * wx);
        for (int pass = 0; pass < LOCAL_PASSES; ++pass) {
            c = blend_sets(c, reg, w, sets);
            if (pass + 1 < LOCAL_PASSES && quad_holds(c, quad, 1))
                break;  // one of the four holds the blend
        }
        p[0] = (uchar)c.s0;
        p[1] = (uchar)c.s1;
        p[2] = (uchar)c.s2;
        const int bin = bin_of(c), t = nearest[bin];
        if (t != bin)
            into_bin(p, t);
    }
}
#endif
#endif

#if DETAIL

// The detail of frame f added to the projected values v (GROUP values: `count` pixels, the
// first at (x, y), pixel p0 and value `first` of the frame). A work-item whose pixels lie in
// one row works on whole vectors; the others (a row's end inside the group) pixel by pixel,
// with the same operations.
void add_detail(uchar *v, const int count, int x, int y, const size_t p0, const size_t first,
                __global const char *restrict vol,
                __global const float *restrict gain, __global const uchar *restrict low,
                __global const uchar *restrict high, __global const uchar *restrict colours,
                __global const float *lay, const int width)
{
#pragma OPENCL FP_CONTRACT OFF
    const int t0 = (int)lay[0] * VH, oy0 = (int)lay[1], ox0 = (int)lay[2];
    const int t1 = (int)lay[3] * VH, oy1 = (int)lay[4], ox1 = (int)lay[5];
    const float w0 = lay[6], w1 = lay[7];
    int row0 = (t0 + (y + oy0) % VH) * VWP, row1 = (t1 + (y + oy1) % VH) * VWP;
    uchar d[GROUP];
    uchar a[GROUP];
    if (count == PIXELS && x + PIXELS <= width) {
        __global const char *v0 = vol + (row0 + (x + ox0) % VW) * CHANNELS;
        __global const char *v1 = vol + (row1 + (x + ox1) % VW) * CHANNELS;
        const float16 gp = vload16(0, gain + p0);
#if CHANNELS == 3
        const float16 gs[3] = {shuffle(gp, (uint16)(0, 0, 0, 1, 1, 1, 2, 2, 2, 3, 3, 3, 4, 4, 4, 5)),
                               shuffle(gp, (uint16)(5, 5, 6, 6, 6, 7, 7, 7, 8, 8, 8, 9, 9, 9, 10, 10)),
                               shuffle(gp, (uint16)(10, 11, 11, 11, 12, 12, 12, 13, 13, 13, 14, 14, 14, 15, 15, 15))};
#else
        const float16 gs[1] = {gp};
#endif
        for (int j = 0; j < CHANNELS; ++j) {
            const float16 n = w0 * convert_float16(vload16(j, v0)) + w1 * convert_float16(vload16(j, v1));
            const float16 val = convert_float16(vload16(j, v)) + gs[j] * n;
            const uchar16 lo = vload16(j, low + first), hi = vload16(j, high + first);
            vstore16(clamp(convert_uchar16_sat_rte(val), lo, hi), j, d);
            vstore16(clamp(vload16(j, v), lo, hi), j, a);
        }
    } else {
        for (int q = 0; q < count; ++q) {
            const int i0 = (row0 + (x + ox0) % VW) * CHANNELS;
            const int i1 = (row1 + (x + ox1) % VW) * CHANNELS;
            for (int c = 0; c < CHANNELS; ++c) {
                const size_t k = first + q * CHANNELS + c;
                const float n = w0 * (float)vol[i0 + c] + w1 * (float)vol[i1 + c];
                const uchar u = convert_uchar_sat_rte((float)v[q * CHANNELS + c] + gain[p0 + q] * n);
                d[q * CHANNELS + c] = clamp(u, low[k], high[k]);
                a[q * CHANNELS + c] = clamp(v[q * CHANNELS + c], low[k], high[k]);
            }
            if (++x == width) {
                x = 0;
                ++y;
                row0 = (t0 + (y + oy0) % VH) * VWP;
                row1 = (t1 + (y + oy1) % VH) * VWP;
            }
        }
    }
    // a colour outside the source's colour set gets no detail
    for (int q = 0; q < count; ++q) {
        const bool inside = colours[BIN(d, q * CHANNELS)] != 0;
        for (int c = 0; c < CHANNELS; ++c)
            v[q * CHANNELS + c] = inside ? d[q * CHANNELS + c] : a[q * CHANNELS + c];
    }
}
#endif

__kernel void project(__global const basis_t *restrict basis,
                      __global const float *restrict mean,
                      __global const float *restrict coef,
                      __global uchar *restrict out,
                      const int n,
                      const int values,
                      const int stride,
                      const int frames,
                      const int width,
                      __global const char *restrict vol,
                      __global const float *restrict gain,
                      __global const uchar *restrict low,
                      __global const uchar *restrict high,
                      __global const uchar *restrict colours,
                      __global const ushort *restrict nearest,
                      __global const uint *restrict local_sets,
                      __global const uchar *restrict local_quads,
                      __global const float *restrict tone,
                      __global const uchar *restrict tone_table)
{
    const size_t g = get_global_id(0);
    const size_t first = g * GROUP;
    if (first >= (size_t)values)
        return;  // the global size is rounded up to whole work-groups
    __global const basis_t *rows = basis + g * (size_t)n * GROUP;
    const size_t pixels = (size_t)values / CHANNELS;
    const size_t p0 = g * PIXELS;
    const int count = (int)min((size_t)PIXELS, pixels - p0);
    const int y0 = (int)(p0 / (size_t)width), x0 = (int)(p0 - (size_t)y0 * width);
    for (int f = 0; f < frames; ++f) {
        __global const float *c = coef + (size_t)f * stride;
        float16 a0 = vload16(0, mean + first);
#if CHANNELS == 3
        float16 a1 = vload16(1, mean + first);
        float16 a2 = vload16(2, mean + first);
#endif
        for (int i = 0; i < n; ++i) {
            const float ci = c[i];
            __global const basis_t *row = rows + (size_t)i * GROUP;
            a0 += ci * LOAD(row, 0);
#if CHANNELS == 3
            a1 += ci * LOAD(row, 1);
            a2 += ci * LOAD(row, 2);
#endif
        }
        uchar v[GROUP];
#if TONE
        to_levels(v, a0, 0, tone, tone_table);
#if CHANNELS == 3
        to_levels(v, a1, 1, tone, tone_table);
        to_levels(v, a2, 2, tone, tone_table);
#endif
#else
        vstore16(convert_uchar16_sat_rte(a0), 0, v);
#if CHANNELS == 3
        vstore16(convert_uchar16_sat_rte(a1), 1, v);
        vstore16(convert_uchar16_sat_rte(a2), 2, v);
#endif
#endif
#if DETAIL
        add_detail(v, count, x0, y0, p0, first, vol, gain, low, high, colours, c + stride - LAYER_FLOATS, width);
#endif
#if LOCAL
        snap_local(v, count, x0, y0, width, local_sets, local_quads, nearest);
#elif GAMUT
        snap_colours(v, count, nearest);
#endif
        __global uchar *o = out + (size_t)f * pixels * PIXEL_BYTES;
#if CHANNELS == 3 && PIXEL_BYTES == 3 && R_AT == 0 && G_AT == 1 && B_AT == 2
        if (count == PIXELS) {
            vstore16(vload16(0, v), 3 * g, o);
            vstore16(vload16(1, v), 3 * g + 1, o);
            vstore16(vload16(2, v), 3 * g + 2, o);
            continue;
        }
#endif
        for (int q = 0; q < count; ++q) {
#if CHANNELS == 3
            put1(v[3 * q], v[3 * q + 1], v[3 * q + 2], o + (p0 + q) * PIXEL_BYTES);
#else
            put1(v[q], v[q], v[q], o + (p0 + q) * PIXEL_BYTES);
#endif
        }
    }
}
