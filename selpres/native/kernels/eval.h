/* selpres evaluation kernels (forward passes and scoring), written once for VL lanes of float64 and
 * included by sgd.c once per vector width it builds: VL = 4 (AVX2: one group of 4 replicas per ymm)
 * and, where the compiler targets AVX-512F, VL = 8 (two groups side by side in a zmm). No include guard:
 * each inclusion instantiates the functions below for the width the includer has just defined (and
 * undefines it at the end):
 *   VL         lanes per vector                VEC        the vector type (__m256d, __m512d)
 *   VOP(op)    the intrinsic op at that width (_mm256_##op, _mm512_##op)
 *   VSIGMOID   the sigmoid (sigmoid4, or sigmoid8: operation for operation the same)
 *   VF(name)   name with the width appended (forward_act_4, forward_act_8, ...)
 * and, once for both widths, NPAT, S, layer_offsets (see sgd.c).
 * Weights w are [P_TOTAL][VL] (lane k is replica r0 + k), activations [TOT_UNITS][VL] per pattern.
 * Every lane sees the same IEEE operations in the same order at either width, so a replica's numbers
 * do not depend on which width ran it, nor on which replicas share its vector.
 */

#define VLOAD(p) VOP(loadu_pd)(p)
#define VSTORE(p, v) VOP(storeu_pd)((p), (v))
#define VSET1(x) VOP(set1_pd)(x)
#define VFMADD(a, b, c) VOP(fmadd_pd)((a), (b), (c))  /* a * b + c, one rounding */

/* Forward pass of patterns n .. n+np-1 of X through the weights w: the activations of pattern n + p end
   in work + p * TOT_UNITS * VL ([TOT_UNITS][VL], the outputs last). */
static inline __attribute__((always_inline)) void
VF(forward_act)(const int np, const double *w, double *work, const double *X, int64_t n)
{
    const int64_t nin = S[0];
    int64_t woff[NL], boff[NL], aoff[NL + 1];
    layer_offsets(woff, boff, aoff);
    double *act[NPAT];
#define EACHP for (int p = 0; p < np; p++)
#pragma GCC unroll 8
    EACHP {
        act[p] = work + p * TOT_UNITS * VL;
#pragma GCC unroll 4
        for (int64_t i = 0; i < nin; i++) VSTORE(act[p] + i * VL, VSET1(X[(n + p) * nin + i]));
    }
#pragma GCC unroll 8
    for (int l = 0; l < NL; l++) {
        const int64_t ni_ = S[l], no = S[l + 1];
        for (int64_t o = 0; o < no; o++) {
            VEC z[NPAT];
            const VEC bias = VLOAD(w + (boff[l] + o) * VL);
#pragma GCC unroll 8
            EACHP z[p] = bias;
#pragma GCC unroll 4
            for (int64_t i = 0; i < ni_; i++) {
                const VEC wv = VLOAD(w + (woff[l] + o * ni_ + i) * VL);
#pragma GCC unroll 8
                EACHP z[p] = VFMADD(wv, VLOAD(act[p] + (aoff[l] + i) * VL), z[p]);
            }
#pragma GCC unroll 8
            EACHP VSTORE(act[p] + (aoff[l + 1] + o) * VL, VSIGMOID(z[p]));
        }
    }
}

/* pattern p's outputs among the activations forward_act left in work */
#define VOUT(work, p) ((work) + ((p) * TOT_UNITS + TOT_UNITS - S[NL]) * VL)

static inline __attribute__((always_inline)) void
VF(forward_patterns)(const int np, const double *w, double *work, const double *X, int64_t n, int64_t N,
                     int64_t r0, double *out)
{
    const int64_t nout = S[NL];
    VF(forward_act)(np, w, work, X, n);
#pragma GCC unroll 8
    EACHP {  /* lane k is replica r0 + k: out[r][n][o] */
        for (int64_t o = 0; o < nout; o++) {
            double v[VL];
            VSTORE(v, VLOAD(VOUT(work, p) + o * VL));
            for (int k = 0; k < VL; k++) out[((r0 + k) * N + n + p) * nout + o] = v[k];
        }
    }
}

/* Outputs of the VL replicas r0 .. r0+VL-1 (weights w) on patterns [n0, n1) of X [N][S[0]], written to
   out [R][N][S[NL]]. work holds NPAT * TOT_UNITS * VL doubles. */
static void VF(forward_range)(const double *w, double *work, const double *X, int64_t n0, int64_t n1,
                              int64_t N, int64_t r0, double *out)
{
    int64_t n = n0;
    for (; n + NPAT <= n1; n += NPAT) VF(forward_patterns)(NPAT, w, work, X, n, N, r0, out);
    for (; n < n1; n++) VF(forward_patterns)(1, w, work, X, n, N, r0, out);
}

/* Squared errors of the VL replicas r0 .. r0+VL-1 (weights w) on the blocks [b0, b1) of bn patterns of
   X, Y: sums[b][r][o] (R replicas in all) gets block b's sum over its patterns of (output - target)^2.
   Pattern n of a block adds into accumulator n mod NPAT (the leftover patterns into accumulator 0), and
   the accumulators are added 0, 1, ..., NPAT-1. work holds NPAT * (TOT_UNITS + MAXW) * VL doubles. */
static void VF(sqerr_blocks)(const double *w, double *work, const double *X, const double *Y, int64_t N,
                             int64_t b0, int64_t b1, int64_t bn, int64_t R, int64_t r0, double *sums)
{
    const int64_t nout = S[NL];
    double *acc = work + NPAT * TOT_UNITS * VL;  /* [NPAT][MAXW][VL] */
    for (int64_t b = b0; b < b1; b++) {
        const int64_t n1 = (b + 1) * bn < N ? (b + 1) * bn : N;
        memset(acc, 0, (size_t)NPAT * MAXW * VL * sizeof(double));
        int64_t n = b * bn;
        for (; n + NPAT <= n1; n += NPAT) {
            VF(forward_act)(NPAT, w, work, X, n);
#pragma GCC unroll 8
            for (int p = 0; p < NPAT; p++)
                for (int64_t o = 0; o < nout; o++) {
                    double *a = acc + (p * MAXW + o) * VL;
                    VEC d = VOP(sub_pd)(VLOAD(VOUT(work, p) + o * VL), VSET1(Y[(n + p) * nout + o]));
                    VSTORE(a, VFMADD(d, d, VLOAD(a)));
                }
        }
        for (; n < n1; n++) {
            VF(forward_act)(1, w, work, X, n);
            for (int64_t o = 0; o < nout; o++) {
                VEC d = VOP(sub_pd)(VLOAD(VOUT(work, 0) + o * VL), VSET1(Y[n * nout + o]));
                VSTORE(acc + o * VL, VFMADD(d, d, VLOAD(acc + o * VL)));
            }
        }
        for (int64_t o = 0; o < nout; o++) {
            VEC s = VLOAD(acc + o * VL);
            for (int p = 1; p < NPAT; p++) s = VOP(add_pd)(s, VLOAD(acc + (p * MAXW + o) * VL));
            double v[VL];
            VSTORE(v, s);
            for (int k = 0; k < VL; k++) sums[(b * R + r0 + k) * nout + o] = v[k];
        }
    }
}

#undef EACHP
#undef VOUT
#undef VLOAD
#undef VSTORE
#undef VSET1
#undef VFMADD
#undef VL
#undef VEC
#undef VOP
#undef VSIGMOID
#undef VF
