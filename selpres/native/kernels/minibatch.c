/* selpres native kernel: mini-batch training of many replicas with today's units and optimizers
 * (selpres_mb_train: one epoch). It does what selpres/engines/minibatch.py (the torch mini-batch engine)
 * does, operation for operation where it can (the same formulas, in the same order; sums over a
 * mini-batch's patterns in presentation order), so the two agree to rounding (tests/test_native_minibatch.py):
 *   hidden units  ACT: 0 sigmoid, 1 tanh, 2 relu, 3 silu, 4 leaky relu (slope 0.01);  output  OUT_SIGMOID: 1 sigmoid, 0 linear
 *   loss          per pattern mse over the outputs; a mini-batch's loss the mean (mean reduction: times
 *                 2 / (nb * nout) in the gradient) or the sum (sum reduction: 1/2 sum e^2) of weight * mse
 *   optimizers    rule 0 sgd (momentum, L2 weight decay), 1 adam (L2), 2 adamw (decoupled), per replica with
 *                 its own step count, as selpres/engines/optim/replica.py writes them
 *   rate          lr * (cosine: 1/2 (1 + cos(pi * clamp(spent / horizon, 0, 1)))), spent the replica's
 *                 presentations so far (set by the caller before each epoch, advanced here by each batch)
 *
 * Built by selpres/native/build.py (bound by selpres/native/minibatch.py) once per topology and units with
 *   cc -O3 -march=native -fPIC -shared -std=c11 -DNL=.. -DSIZES=.. -DP_TOTAL=.. -DTOT_UNITS=.. -DMAXW=.. \
 *      -DACT=.. -DOUT_SIGMOID=.. -DNP=..
 * (NL, SIZES, P_TOTAL, TOT_UNITS, MAXW as for sgd.c; NP: patterns advanced together, see present()).
 *
 * Layout: sgd.c's. Replicas in groups of 4 lanes, one AVX2 vector of float64 per parameter; a group's
 * parameters contiguous as [P_TOTAL][4] (W1 row-major [out][in], b1, W2, b2, ...), and the optimizer's
 * state (M1: momentum buffer or Adam's first moment, M2: Adam's second moment) the same way. Lanes never
 * mix, and every lane sees the same operations in the same order however groups are split among
 * threads, so the numbers do not depend on the thread count.
 *
 * Within a mini-batch the weights do not change, so its patterns are independent until the update: NP of
 * them go through the forward and backward passes together (one weight load feeds NP FMAs, NP sigmoid
 * chains overlap), and their gradients are added into the batch's gradient pattern by pattern in order.
 */
#include <immintrin.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#ifndef __AVX2__
#error "selpres kernel needs AVX2"
#endif
#ifndef __FMA__
#error "selpres kernel needs FMA"
#endif
#if !defined(NL) || !defined(SIZES) || !defined(P_TOTAL) || !defined(TOT_UNITS) || !defined(MAXW) \
    || !defined(ACT) || !defined(OUT_SIGMOID) || !defined(NP)
#error "compile with -DNL -DSIZES -DP_TOTAL -DTOT_UNITS -DMAXW -DACT -DOUT_SIGMOID -DNP (see the header comment)"
#endif

static const int64_t S[NL + 1] = {SIZES};

#define LD(p) _mm256_loadu_pd(p)
#define ST(p, v) _mm256_storeu_pd((p), (v))
#define SET1(x) _mm256_set1_pd(x)

#include "exp4.h"
#include "layout.h"

/* expm1(x) for x <= 0 (tanh4's argument): degree-13 Taylor where |x| < 0.35 (truncation < 2e-17 relative),
   exp4(x) - 1 elsewhere (|exp(x) - 1| >= 0.29 there, so the subtraction loses under a bit). */
static inline __m256d expm1_neg4(__m256d x)
{
    static const double inv_fact[13] = {1.0 / 6227020800.0, 1.0 / 479001600.0, 1.0 / 39916800.0,
                                        1.0 / 3628800.0,    1.0 / 362880.0,    1.0 / 40320.0,
                                        1.0 / 5040.0,       1.0 / 720.0,       1.0 / 120.0,
                                        1.0 / 24.0,         1.0 / 6.0,         0.5, 1.0};
    __m256d p = SET1(inv_fact[0]);
    for (int k = 1; k < 13; k++) p = _mm256_fmadd_pd(p, x, SET1(inv_fact[k]));
    const __m256d small = _mm256_mul_pd(p, x);
    const __m256d large = _mm256_sub_pd(exp4(x), SET1(1.0));
    const __m256d is_small = _mm256_cmp_pd(x, SET1(-0.35), _CMP_GT_OQ);
    return _mm256_blendv_pd(large, small, is_small);
}

/* tanh(z) = sign(z) * -e / (2 + e) with e = expm1(-2|z|): accurate in relative terms near 0 too. */
static inline __m256d tanh4(__m256d z)
{
    const __m256d sign = _mm256_and_pd(z, SET1(-0.0));
    const __m256d e = expm1_neg4(_mm256_mul_pd(SET1(-2.0), _mm256_andnot_pd(SET1(-0.0), z)));
    const __m256d t = _mm256_div_pd(_mm256_xor_pd(e, SET1(-0.0)), _mm256_add_pd(SET1(2.0), e));
    return _mm256_or_pd(t, sign);
}

/* A hidden unit: its activation *a and derivative *d (d act / dz) from the pre-activation z, with the torch
   engine's formulas (selpres/engines/minibatch.py _act, _act_prime). */
static inline void hidden4(__m256d z, __m256d *a, __m256d *d)
{
    const __m256d one = SET1(1.0);
#if ACT == 0
    *a = sigmoid4(z);
    *d = _mm256_mul_pd(*a, _mm256_sub_pd(one, *a));
#elif ACT == 1
    *a = tanh4(z);
    *d = _mm256_sub_pd(one, _mm256_mul_pd(*a, *a));
#elif ACT == 2
    *a = _mm256_max_pd(_mm256_setzero_pd(), z); /* operand order keeps NaN */
    *d = _mm256_and_pd(_mm256_cmp_pd(z, _mm256_setzero_pd(), _CMP_GT_OQ), one);
#elif ACT == 3
    const __m256d s = sigmoid4(z);
    *a = _mm256_mul_pd(z, s);
    *d = _mm256_mul_pd(s, _mm256_add_pd(one, _mm256_mul_pd(z, _mm256_sub_pd(one, s))));
#elif ACT == 4
    /* z > 0 ? z : 0.01 z, as torch.where(z > 0, z, 0.01 * z) (a NaN takes the slope branch and stays NaN) */
    const __m256d pos = _mm256_cmp_pd(z, _mm256_setzero_pd(), _CMP_GT_OQ);
    *a = _mm256_blendv_pd(_mm256_mul_pd(SET1(0.01), z), z, pos);
    *d = _mm256_blendv_pd(SET1(0.01), one, pos);
#else
#error "ACT: 0 sigmoid, 1 tanh, 2 relu, 3 silu, 4 leaky_relu"
#endif
}

/* one pattern's work arrays: activations and derivatives [TOT_UNITS][4], two delta buffers [MAXW][4] */
#define PAT_DOUBLES ((2 * TOT_UNITS + 2 * MAXW) * 4)

/* Register blocking. The passes are small matrix products per lane (patterns x units), bound by loads when each
   product reloads its operands: blocks of 2 units x PB patterns keep 8 accumulators in registers, each weight
   or activation loaded once per block (0.75 loads a multiply-add, from 1.1 - 2). Every value is still summed in
   the same order (inputs, outputs, patterns in turn), so blocking changes no number. */
#define PB(np) ((np) < 4 ? (np) : 4)

/* z[p][o0 + k] (k < nk <= 2) of patterns p0 .. p0 + PB - 1: bias + sum over the inputs i, in order, of w a. */
static inline __attribute__((always_inline)) void
forward_block(const int nk, const int pb, const double *w, int64_t woff, int64_t boff, int64_t ni_, int64_t o0,
              double *const *act, int64_t ain, int p0, __m256d z[2][4])
{
#pragma GCC unroll 2
    for (int k = 0; k < nk; k++) {
        const __m256d bias = LD(w + (boff + o0 + k) * 4);
#pragma GCC unroll 4
        for (int p = 0; p < pb; p++) z[k][p] = bias;
    }
#pragma GCC unroll 4
    for (int64_t i = 0; i < ni_; i++) {
        __m256d wv[2];
#pragma GCC unroll 2
        for (int k = 0; k < nk; k++) wv[k] = LD(w + (woff + (o0 + k) * ni_ + i) * 4);
#pragma GCC unroll 4
        for (int p = 0; p < pb; p++) {
            const __m256d a = LD(act[p0 + p] + (ain + i) * 4);
#pragma GCC unroll 2
            for (int k = 0; k < nk; k++) z[k][p] = _mm256_fmadd_pd(wv[k], a, z[k][p]);
        }
    }
}

/* dn[p][i0 + k] of patterns p0 .. p0 + PB - 1: (sum over the outputs o, in order, of w[o][i] d[p][o]) * act'. */
static inline __attribute__((always_inline)) void
delta_block(const int nk, const int pb, const double *w, int64_t woff, int64_t ni_, int64_t no, int64_t i0,
            double *const *d, double *const *dn, double *const *dact, int64_t ain, int p0)
{
    __m256d acc[2][4];
#pragma GCC unroll 2
    for (int k = 0; k < nk; k++)
#pragma GCC unroll 4
        for (int p = 0; p < pb; p++) acc[k][p] = _mm256_setzero_pd();
#pragma GCC unroll 4
    for (int64_t o = 0; o < no; o++) {
        __m256d wv[2];
#pragma GCC unroll 2
        for (int k = 0; k < nk; k++) wv[k] = LD(w + (woff + o * ni_ + i0 + k) * 4);
#pragma GCC unroll 4
        for (int p = 0; p < pb; p++) {
            const __m256d dv = LD(d[p0 + p] + o * 4);
#pragma GCC unroll 2
            for (int k = 0; k < nk; k++) acc[k][p] = _mm256_fmadd_pd(wv[k], dv, acc[k][p]);
        }
    }
#pragma GCC unroll 2
    for (int k = 0; k < nk; k++)
#pragma GCC unroll 4
        for (int p = 0; p < pb; p++)
            ST(dn[p0 + p] + (i0 + k) * 4, _mm256_mul_pd(acc[k][p], LD(dact[p0 + p] + (ain + i0 + k) * 4)));
}

/* G[o0 + k][i0 + c] (k < nk <= 2, c < nc <= 4) += sum over the np patterns, in order, of d[p][o] a[p][i]
   (masked, np = 1: only on the lanes live[0] sets). */
static inline __attribute__((always_inline)) void
grad_block(const int np, const int masked, const int nk, const int nc, double *G, int64_t woff, int64_t ni_,
           int64_t o0, int64_t i0, double *const *d, double *const *act, int64_t ain, const __m256d *live)
{
    __m256d acc[2][4];
#pragma GCC unroll 2
    for (int k = 0; k < nk; k++)
#pragma GCC unroll 4
        for (int c = 0; c < nc; c++) acc[k][c] = LD(G + (woff + (o0 + k) * ni_ + i0 + c) * 4);
#pragma GCC unroll 8
    for (int p = 0; p < np; p++) {
        __m256d dv[2];
#pragma GCC unroll 2
        for (int k = 0; k < nk; k++) dv[k] = LD(d[p] + (o0 + k) * 4);
#pragma GCC unroll 4
        for (int c = 0; c < nc; c++) {
            const __m256d a = LD(act[p] + (ain + i0 + c) * 4);
#pragma GCC unroll 2
            for (int k = 0; k < nk; k++) acc[k][c] = _mm256_fmadd_pd(dv[k], a, acc[k][c]);
        }
    }
#pragma GCC unroll 2
    for (int k = 0; k < nk; k++)
#pragma GCC unroll 4
        for (int c = 0; c < nc; c++) {
            double *g = G + (woff + (o0 + k) * ni_ + i0 + c) * 4;
            ST(g, masked ? _mm256_blendv_pd(LD(g), acc[k][c], live[0]) : acc[k][c]);
        }
}

/* Patterns j .. j+np-1 of the 4 lanes' orders (ord[q] is lane q's row) through the weights w: forward,
   per-pattern loss (mse over the outputs) into pl[p], and their gradients, scaled per lane by scale[p]
   (2 / (nb * nout) * weight, or the weight alone), added into G pattern by pattern. masked (np = 1 only): the
   lanes where live[0] is clear add nothing (blends, so a NaN there cannot leak into the batch's gradient). */
static inline __attribute__((always_inline)) void
present(const int np, const int masked, const double *w, double *G, double *work, const double *X,
        const double *Y, const int64_t *const *ord, int64_t j, int64_t ldx, int64_t ldy, const __m256d *scale,
        const __m256d *live, __m256d *pl)
{
    const int64_t nin = S[0], nout = S[NL];
    int64_t woff[NL], boff[NL], aoff[NL + 1];
    layer_offsets(woff, boff, aoff);
    const __m256d one = SET1(1.0);
    double *act[NP], *dact[NP], *d[NP], *dn[NP];
#define EACHP for (int p = 0; p < np; p++)
#pragma GCC unroll 8
    EACHP {
        act[p] = work + p * PAT_DOUBLES;
        dact[p] = act[p] + TOT_UNITS * 4;
        d[p] = dact[p] + TOT_UNITS * 4;
        dn[p] = d[p] + MAXW * 4;
        const double *x0 = X + ord[0][j + p] * ldx, *x1 = X + ord[1][j + p] * ldx;
        const double *x2 = X + ord[2][j + p] * ldx, *x3 = X + ord[3][j + p] * ldx;
#pragma GCC unroll 4
        for (int64_t i = 0; i < nin; i++) ST(act[p] + i * 4, _mm256_set_pd(x3[i], x2[i], x1[i], x0[i]));
    }
    /* forward, in blocks of 2 units x PB patterns */
#pragma GCC unroll 8
    for (int l = 0; l < NL; l++) {
        const int64_t ni_ = S[l], no = S[l + 1];
        for (int p0 = 0; p0 < np; p0 += PB(np)) {
            for (int64_t o0 = 0; o0 < no; o0 += 2) {
                const int nk = no - o0 >= 2 ? 2 : 1;
                __m256d z[2][4];
                if (nk == 2)
                    forward_block(2, PB(np), w, woff[l], boff[l], ni_, o0, act, aoff[l], p0, z);
                else
                    forward_block(1, PB(np), w, woff[l], boff[l], ni_, o0, act, aoff[l], p0, z);
#pragma GCC unroll 2
                for (int k = 0; k < nk; k++)
#pragma GCC unroll 4
                    for (int p = 0; p < PB(np); p++) {
                        __m256d a, da;
                        if (l < NL - 1) {
                            hidden4(z[k][p], &a, &da);
                            ST(dact[p0 + p] + (aoff[l + 1] + o0 + k) * 4, da);
                        } else {
                            a = OUT_SIGMOID ? sigmoid4(z[k][p]) : z[k][p];
                        }
                        ST(act[p0 + p] + (aoff[l + 1] + o0 + k) * 4, a);
                    }
            }
        }
    }
    /* output deltas: (y - t) * scale (sigmoid output: times y (1 - y)); the loss: mean over outputs of (y - t)^2 */
#pragma GCC unroll 8
    EACHP {
        const double *y = act[p] + aoff[NL] * 4;
        const double *t0 = Y + ord[0][j + p] * ldy, *t1 = Y + ord[1][j + p] * ldy;
        const double *t2 = Y + ord[2][j + p] * ldy, *t3 = Y + ord[3][j + p] * ldy;
        __m256d sq = _mm256_setzero_pd();
        for (int64_t o = 0; o < nout; o++) {
            const __m256d yv = LD(y + o * 4);
            const __m256d diff = _mm256_sub_pd(yv, _mm256_set_pd(t3[o], t2[o], t1[o], t0[o]));
            sq = _mm256_add_pd(sq, _mm256_mul_pd(diff, diff));
            __m256d dv = _mm256_mul_pd(diff, scale[p]);
            if (OUT_SIGMOID) dv = _mm256_mul_pd(_mm256_mul_pd(dv, yv), _mm256_sub_pd(one, yv));
            ST(d[p] + o * 4, dv);
        }
        pl[p] = _mm256_div_pd(sq, SET1((double)nout));
    }
    /* backward, layer by layer: the deltas of the layer below, then the layer's gradient added into G */
#pragma GCC unroll 8
    for (int l = NL - 1; l >= 0; l--) {
        const int64_t ni_ = S[l], no = S[l + 1];
        if (l > 0) {
            for (int p0 = 0; p0 < np; p0 += PB(np))
                for (int64_t i0 = 0; i0 < ni_; i0 += 2) {
                    if (ni_ - i0 >= 2)
                        delta_block(2, PB(np), w, woff[l], ni_, no, i0, d, dn, dact, aoff[l], p0);
                    else
                        delta_block(1, PB(np), w, woff[l], ni_, no, i0, d, dn, dact, aoff[l], p0);
                }
        }
        for (int64_t o0 = 0; o0 < no; o0 += 2) {
            const int nk = no - o0 >= 2 ? 2 : 1;
            int64_t i0 = 0;
            for (; i0 + 4 <= ni_; i0 += 4) {
                if (nk == 2)
                    grad_block(np, masked, 2, 4, G, woff[l], ni_, o0, i0, d, act, aoff[l], live);
                else
                    grad_block(np, masked, 1, 4, G, woff[l], ni_, o0, i0, d, act, aoff[l], live);
            }
            for (; i0 < ni_; i0++) {
                if (nk == 2)
                    grad_block(np, masked, 2, 1, G, woff[l], ni_, o0, i0, d, act, aoff[l], live);
                else
                    grad_block(np, masked, 1, 1, G, woff[l], ni_, o0, i0, d, act, aoff[l], live);
            }
#pragma GCC unroll 2
            for (int k = 0; k < nk; k++) {
                double *gb = G + (boff[l] + o0 + k) * 4;
                const __m256d b0 = LD(gb);
                __m256d b = b0;
#pragma GCC unroll 8
                EACHP b = _mm256_add_pd(b, LD(d[p] + (o0 + k) * 4));
                ST(gb, masked ? _mm256_blendv_pd(b0, b, live[0]) : b);
            }
        }
#pragma GCC unroll 8
        EACHP {
            double *tmp = d[p];
            d[p] = dn[p];
            dn[p] = tmp;
        }
    }
#undef EACHP
}

enum { RULE_SGD = 0, RULE_ADAM = 1, RULE_ADAMW = 2 };
enum { HP_LR, HP_MOMENTUM, HP_BETA1, HP_BETA2, HP_EPS, HP_WD, HP_HORIZON, HP_COUNT };
enum { FL_RULE, FL_COSINE, FL_MEAN, FL_COUNT };

/* The update of one group from its batch gradient G, on the lanes with step set (the others keep weights and
   state bit for bit): selpres/engines/optim/replica.py's formulas, lane by lane its own rate and step count. */
static void update(const int64_t *fl, const double *hp, double *w, double *m1, double *m2, const double *G,
                   const double lr[4], const double t[4], __m256d step)
{
    const double wd = hp[HP_WD];
    const __m256d vlr = _mm256_loadu_pd(lr), vwd = SET1(wd);
    if (fl[FL_RULE] == RULE_SGD) { /* g += wd p; buf = mom buf + g; p -= lr buf */
        const __m256d mom = SET1(hp[HP_MOMENTUM]);
        for (int64_t p = 0; p < P_TOTAL; p++) {
            const __m256d w0 = LD(w + p * 4), b0 = LD(m1 + p * 4);
            __m256d g = LD(G + p * 4);
            if (wd != 0.0) g = _mm256_add_pd(g, _mm256_mul_pd(vwd, w0));
            const __m256d b = _mm256_add_pd(_mm256_mul_pd(b0, mom), g);
            const __m256d wn = _mm256_sub_pd(w0, _mm256_mul_pd(vlr, b));
            ST(m1 + p * 4, _mm256_blendv_pd(b0, b, step));
            ST(w + p * 4, _mm256_blendv_pd(w0, wn, step));
        }
        return;
    }
    const double b1 = hp[HP_BETA1], b2 = hp[HP_BETA2];
    double size[4], bc2[4];
    for (int q = 0; q < 4; q++) { /* lr / (1 - b1^t), sqrt(1 - b2^t) */
        size[q] = lr[q] / (1.0 - pow(b1, t[q]));
        bc2[q] = sqrt(1.0 - pow(b2, t[q]));
    }
    const __m256d vsize = _mm256_loadu_pd(size), vbc2 = _mm256_loadu_pd(bc2), eps = SET1(hp[HP_EPS]);
    const __m256d vb1 = SET1(b1), vb2 = SET1(b2), c1 = SET1(1.0 - b1), c2 = SET1(1.0 - b2);
    const int adamw = fl[FL_RULE] == RULE_ADAMW;
    const __m256d decay = _mm256_sub_pd(SET1(1.0), _mm256_mul_pd(vlr, vwd)); /* adamw: p *= 1 - lr wd */
    for (int64_t p = 0; p < P_TOTAL; p++) {
        const __m256d w0 = LD(w + p * 4), mo = LD(m1 + p * 4), vo = LD(m2 + p * 4);
        __m256d g = LD(G + p * 4);
        if (!adamw && wd != 0.0) g = _mm256_add_pd(g, _mm256_mul_pd(vwd, w0));
        const __m256d mn = _mm256_add_pd(_mm256_mul_pd(mo, vb1), _mm256_mul_pd(g, c1));
        const __m256d vn = _mm256_add_pd(_mm256_mul_pd(vo, vb2), _mm256_mul_pd(_mm256_mul_pd(g, g), c2));
        const __m256d denom = _mm256_add_pd(_mm256_div_pd(_mm256_sqrt_pd(vn), vbc2), eps);
        const __m256d base = adamw ? _mm256_mul_pd(w0, decay) : w0;
        const __m256d wn = _mm256_sub_pd(base, _mm256_div_pd(_mm256_mul_pd(vsize, mn), denom));
        ST(m1 + p * 4, _mm256_blendv_pd(mo, mn, step));
        ST(m2 + p * 4, _mm256_blendv_pd(vo, vn, step));
        ST(w + p * 4, _mm256_blendv_pd(w0, wn, step));
    }
}

#define PI 3.141592653589793

/* One epoch of mini-batches for groups [g0, g1). W, M1, M2 [G][P_TOTAL][4] (updated in place); T [G*4] each
   lane's optimizer steps so far and spent [G*4] its presentations so far (both advanced); order [G*4][m];
   counts [G*4] (NULL: m each) the patterns each lane presents, its first counts of its row of order; wts
   [G*4][m] (NULL: 1) each pattern's weight; loss [G*4] gets each lane's sum of its patterns' mse and
   plosses [G*4][m] each presented pattern's mse (before the batch's update; the rest left as they were).
   Lane q's mini-batch from s holds nb = min(B, count - s) patterns; a lane with none does not step.
   hp: lr, momentum, beta1, beta2, eps, weight decay, horizon; fl: rule, cosine, mean reduction.
   X, Y rows: ldx, ldy apart. Returns 0, -1 (out of memory) or -3 (not the topology compiled in). */
int selpres_mb_train(int nl, const int64_t *sizes, int64_t g0, int64_t g1, int64_t P, double *W, double *M1,
                     double *M2, double *T, double *spent, const double *X, const double *Y, const int64_t *order,
                     int64_t m, int64_t B, const double *hp, const int64_t *fl, double *loss, double *plosses,
                     int64_t ldx, int64_t ldy, const int64_t *counts, const double *wts)
{
    if (nl != NL || P != P_TOTAL || B < 1) return -3;
    for (int l = 0; l <= NL; l++)
        if (sizes[l] != S[l]) return -3;
    if (ldx < S[0] || ldy < S[NL]) return -3;
    double *work = (double *)aligned_alloc(32, (size_t)NP * PAT_DOUBLES * 8);
    double *G = (double *)aligned_alloc(32, (size_t)P_TOTAL * 32);
    if (!work || !G) {
        free(work);
        free(G);
        return -1;
    }
    const int64_t nout = S[NL];
    const double horizon = hp[HP_HORIZON] > 1e-300 ? hp[HP_HORIZON] : 1e-300;
    for (int64_t g = g0; g < g1; g++) {
        double *w = W + g * P_TOTAL * 4, *m1 = M1 + g * P_TOTAL * 4, *m2 = M2 + g * P_TOTAL * 4;
        const int64_t *ord[4];
        int64_t cnt[4], mend = 0;
        for (int q = 0; q < 4; q++) {
            ord[q] = order + (g * 4 + q) * m;
            const int64_t c = counts ? counts[g * 4 + q] : m;
            cnt[q] = c < 0 ? 0 : (c > m ? m : c);
            if (cnt[q] > mend) mend = cnt[q];
        }
        __m256d lsum = _mm256_setzero_pd();
        for (int64_t s = 0; s < mend; s += B) {
            const int64_t bs = mend - s < B ? mend - s : B;
            int64_t nb[4];
            double c[4], lr[4], t[4], stepd[4];
            int full = 1;
            for (int q = 0; q < 4; q++) {
                const int64_t left = cnt[q] - s;
                nb[q] = left < 0 ? 0 : (left < B ? left : B);
                full &= nb[q] == bs;
                c[q] = nb[q] > 0 && fl[FL_MEAN] ? 2.0 / (double)(nb[q] * nout) : 1.0;
                double f = 1.0;
                if (fl[FL_COSINE]) {
                    double frac = spent[g * 4 + q] / horizon;
                    frac = frac < 0.0 ? 0.0 : (frac > 1.0 ? 1.0 : frac);
                    f = 0.5 * (1.0 + cos(PI * frac));
                }
                lr[q] = hp[HP_LR] * f;
                t[q] = T[g * 4 + q] + (nb[q] > 0 ? 1.0 : 0.0);
                stepd[q] = nb[q] > 0 ? -1.0 : 0.0; /* sign bit set: the lane steps (blendv reads it) */
            }
            memset(G, 0, (size_t)P_TOTAL * 32);
            __m256d scale[NP], live[NP], pl[NP];
            int64_t k = 0;
            if (full) {
                for (; k + NP <= bs; k += NP) {
                    for (int p = 0; p < NP; p++) {
                        const int64_t j = s + k + p;
                        double sc[4];
                        for (int q = 0; q < 4; q++) sc[q] = wts ? c[q] * wts[(g * 4 + q) * m + j] : c[q];
                        scale[p] = _mm256_loadu_pd(sc);
                    }
                    present(NP, 0, w, G, work, X, Y, ord, s + k, ldx, ldy, scale, live, pl);
                    for (int p = 0; p < NP; p++) {
                        const int64_t j = s + k + p;
                        double v[4];
                        lsum = _mm256_add_pd(lsum, pl[p]);
                        _mm256_storeu_pd(v, pl[p]);
                        for (int q = 0; q < 4; q++) plosses[(g * 4 + q) * m + j] = v[q];
                    }
                }
            }
            for (; k < bs; k++) { /* the rest one by one, each lane masked past its own count */
                const int64_t j = s + k;
                double sc[4], lv[4];
                for (int q = 0; q < 4; q++) {
                    const int on = j < cnt[q];
                    lv[q] = on ? -1.0 : 0.0;
                    sc[q] = on ? (wts ? c[q] * wts[(g * 4 + q) * m + j] : c[q]) : 0.0;
                }
                scale[0] = _mm256_loadu_pd(sc);
                live[0] = _mm256_loadu_pd(lv);
                present(1, 1, w, G, work, X, Y, ord, j, ldx, ldy, scale, live, pl);
                double v[4];
                lsum = _mm256_add_pd(lsum, _mm256_blendv_pd(_mm256_setzero_pd(), pl[0], live[0]));
                _mm256_storeu_pd(v, pl[0]);
                for (int q = 0; q < 4; q++)
                    if (j < cnt[q]) plosses[(g * 4 + q) * m + j] = v[q];
            }
            update(fl, hp, w, m1, m2, G, lr, t, _mm256_loadu_pd(stepd));
            for (int q = 0; q < 4; q++) {
                T[g * 4 + q] = t[q];
                spent[g * 4 + q] += (double)nb[q];
            }
        }
        double ls[4];
        _mm256_storeu_pd(ls, lsum);
        for (int q = 0; q < 4; q++) loss[g * 4 + q] = ls[q];
    }
    free(work);
    free(G);
    return 0;
}
