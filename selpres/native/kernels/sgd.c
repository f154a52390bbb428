/* selpres native kernel: SGD with momentum for many replicas of a sigmoid back-propagation network
 * (selpres_train: one epoch), their forward passes (selpres_forward: evaluation), their squared errors
 * summed inside the forward pass (selpres_sqerr: scoring), and whether their weights are finite
 * (selpres_finite: the divergence check). The evaluation code is in eval.h, built here at 4 lanes and,
 * where the compiler targets AVX-512F, at 8 (selpres_eval_lanes says which).
 *
 * Built by selpres/native/build.py (bound by selpres/native/sgd.py), which compiles this file once per
 * topology with
 *   cc -O3 -march=native -fPIC -shared -std=c11 \
 *      -DNL=.. -DSIZES=.. -DP_TOTAL=.. -DTOT_UNITS=.. -DMAXW=.. -DNI=..
 *   NL         number of weight layers (6-13-2: 2)
 *   SIZES      the layer widths, comma separated (6-13-2: 6,13,2)
 *   P_TOTAL    parameters of one replica: sum over layers of out*in + out
 *   TOT_UNITS  sum of SIZES (activations of one presentation)
 *   MAXW       the widest layer
 *   NI         groups advanced together in one instruction stream (see train_groups)
 * Work arrays (activations, deltas) live on the heap, one block per call, so no topology can overflow a
 * thread's stack.
 *
 * Layout: replicas in groups of 4 lanes, one AVX2 vector of float64 per parameter; a group's parameters
 * are contiguous as [P_TOTAL][4] in the order W1 (row-major [out][in]), b1, W2, b2, ...
 * Every replica sees exactly the operations of torch.optim.SGD(lr, momentum) on mse_loss, in a fixed
 * order, so results do not depend on how replicas are grouped or threaded.
 */
#include <immintrin.h>
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
    || !defined(NI)
#error "compile with -DNL -DSIZES -DP_TOTAL -DTOT_UNITS -DMAXW -DNI (see the header comment)"
#endif

static const int64_t S[NL + 1] = {SIZES};

#define PF 8  /* prefetch distance in presentations (see train_groups) */

#define LD(p) _mm256_loadu_pd(p)
#define ST(p, v) _mm256_storeu_pd((p), (v))

#include "exp4.h"

#include "layout.h"

#define WORK_DOUBLES ((TOT_UNITS + 2 * MAXW) * 4)  /* one group's work arrays */

/* Interleave. One presentation is a long chain of dependent operations (forward with ~90-cycle
   sigmoid chains, backward, update; the next presentation reads the updated weights), so a single
   group of 4 replicas leaves the core partly idle. train_groups() therefore advances ni independent
   groups in one instruction stream (every value is an array of ni vectors, one per group) and the CPU
   overlaps their chains (~1.3x at 6-13-2; the update's loads/stores then bound it). Each replica still
   sees exactly the same sequence of IEEE operations, so results do not depend on how replicas are
   grouped. Called with ni = NI, then ni = 1 for a leftover group. Loops are unrolled by 4 only: fully
   unrolled, the interleaved code was slower.

   Pruned epochs (masked = 1; selpres/presentation/pruning.py): lane k of group g presents only the first
   cnt = counts[g*4 + k] entries of its row of order, pattern j's gradient scaled by wts[(g*4 + k) * m + j]
   (InfoBatch's 1/(1 - r); NULL: 1), and plosses[(g*4 + k) * m + j] gets pattern j's loss (mean over the
   outputs of (y - t)^2, before its update; NULL: not written). A lane's mini-batches are its own: the one
   from s holds nb = min(B, cnt - s) patterns, each scaled by 2 / (nb * nout) * weight, so a lane with
   nothing left (nb = 0) is masked out of the update: its weights and momenta are kept bit for bit (blends,
   not arithmetic with zeros, which a NaN would defeat). masked is a constant at each call site, so the
   usual epoch (masked = 0) compiles to the code it always was. */
static inline __attribute__((always_inline)) void
train_groups(const int ni, const int masked, int64_t g, double *W, double *M, double *Gb, double *work,
             const double *X, const double *Y, const int64_t *order, int64_t m, int64_t B,
             double lr, double mom, double *loss, int64_t ldx, int64_t ldy,
             const int64_t *counts, const double *wts, double *plosses)
{
    const int64_t nin = S[0], nout = S[NL];
    int64_t woff[NL], boff[NL], aoff[NL + 1];
    layer_offsets(woff, boff, aoff);
    /* per group: activations [TOT_UNITS][4] and two delta buffers [MAXW][4], in `work` */
    double *act[NI], *da[NI], *db[NI];
    double *w[NI], *mb[NI], *G[NI];
    const int64_t *ord[NI][4];
    __m256d lsum[NI];
    int64_t cnt[NI][4];       /* masked: patterns each lane presents (clamped to [0, m]) */
    __m256i vcnt[NI];
    __m256d scale[NI], live[NI], blive[NI];  /* per step: gradient scale, lane presents j, lane steps */
    int64_t mend = m;         /* masked: the steps any lane of these groups presents */
    const __m256d one = _mm256_set1_pd(1.0);
    const __m256d vmom = _mm256_set1_pd(mom), vlr = _mm256_set1_pd(lr);

#define EACH for (int u = 0; u < ni; u++)
#pragma GCC unroll 4
    EACH {
        w[u] = W + (g + u) * P_TOTAL * 4;
        mb[u] = M + (g + u) * P_TOTAL * 4;
        G[u] = Gb + u * P_TOTAL * 4;
        act[u] = work + u * WORK_DOUBLES;
        da[u] = act[u] + TOT_UNITS * 4;
        db[u] = da[u] + MAXW * 4;
        for (int k = 0; k < 4; k++) ord[u][k] = order + ((g + u) * 4 + k) * m;
        lsum[u] = _mm256_setzero_pd();
    }
    if (masked) {
        mend = 0;
        EACH {
            for (int k = 0; k < 4; k++) {
                int64_t c = counts ? counts[(g + u) * 4 + k] : m;
                cnt[u][k] = c < 0 ? 0 : (c > m ? m : c);
                if (cnt[u][k] > mend) mend = cnt[u][k];
            }
            vcnt[u] = _mm256_set_epi64x(cnt[u][3], cnt[u][2], cnt[u][1], cnt[u][0]);
        }
    }
    for (int64_t s = 0; s < mend; s += B) {
        const int64_t bs = (mend - s < B) ? (mend - s) : B;
        const __m256d bscale = _mm256_set1_pd(2.0 / (double)(bs * nout));
        double lscale[NI][4];   /* masked: each lane's 2 / (nb * nout) for this mini-batch (0: no step) */
        if (masked) {
            EACH {
                for (int q = 0; q < 4; q++) {
                    const int64_t left = cnt[u][q] - s, nb = left < B ? left : B;
                    lscale[u][q] = nb > 0 ? 2.0 / (double)(nb * nout) : 0.0;
                }
                blive[u] = _mm256_castsi256_pd(_mm256_cmpgt_epi64(vcnt[u], _mm256_set1_epi64x(s)));
            }
        }
        if (B > 1) memset(Gb, 0, (size_t)ni * P_TOTAL * 32);
        for (int64_t k = 0; k < bs; k++) {
            const int64_t j = s + k;
            if (masked) {
                EACH {
                    double sc[4];
                    for (int q = 0; q < 4; q++)
                        sc[q] = j < cnt[u][q] ? (wts ? lscale[u][q] * wts[((g + u) * 4 + q) * m + j] : lscale[u][q])
                                              : 0.0;
                    scale[u] = _mm256_set_pd(sc[3], sc[2], sc[1], sc[0]);
                    live[u] = _mm256_castsi256_pd(_mm256_cmpgt_epi64(vcnt[u], _mm256_set1_epi64x(j)));
                }
            } else {
                EACH scale[u] = bscale;
            }
            /* prefetch the rows presented PF steps ahead, every cache line of them: on sets larger than
               the caches every row is a random fetch from memory, which would otherwise stall each step
               (issue 11, item 9; 18 inputs span 3 lines, of which first and last alone missed one) */
            if (j + PF < mend) {
#pragma GCC unroll 4
                EACH for (int q = 0; q < 4; q++) {
                    const int64_t r = ord[u][q][j + PF];
                    const char *xr = (const char *)(X + r * ldx), *yr = (const char *)(Y + r * ldy);
                    for (int64_t b = 0; b < nin * 8; b += 64) __builtin_prefetch(xr + b);
                    __builtin_prefetch(xr + nin * 8 - 1);
                    for (int64_t b = 0; b < nout * 8; b += 64) __builtin_prefetch(yr + b);
                    __builtin_prefetch(yr + nout * 8 - 1);
                }
            }
            /* forward: inputs of the 4 lanes' patterns, then each layer's sigmoid units */
#pragma GCC unroll 4
            EACH {
                const double *x0 = X + ord[u][0][j] * ldx, *x1 = X + ord[u][1][j] * ldx;
                const double *x2 = X + ord[u][2][j] * ldx, *x3 = X + ord[u][3][j] * ldx;
#pragma GCC unroll 4
                for (int64_t i = 0; i < nin; i++)
                    ST(act[u] + i * 4, _mm256_set_pd(x3[i], x2[i], x1[i], x0[i]));
            }
#pragma GCC unroll 8
            for (int l = 0; l < NL; l++) {
                const int64_t ni_ = S[l], no = S[l + 1];
#pragma GCC unroll 4
                for (int64_t o = 0; o < no; o++) {
                    __m256d z[NI];
#pragma GCC unroll 4
                    EACH z[u] = LD(w[u] + (boff[l] + o) * 4);
#pragma GCC unroll 4
                    for (int64_t i = 0; i < ni_; i++) {
#pragma GCC unroll 4
                        EACH z[u] = _mm256_fmadd_pd(LD(w[u] + (woff[l] + o * ni_ + i) * 4),
                                                    LD(act[u] + (aoff[l] + i) * 4), z[u]);
                    }
#pragma GCC unroll 4
                    EACH ST(act[u] + (aoff[l + 1] + o) * 4, sigmoid4(z[u]));
                }
            }
            /* output deltas dL/dz = 2 (y - t) / (bs * nout) * y (1 - y) (masked: times the pattern's
               weight); the loss sums (y - t)^2 (masked: of the presented patterns only) */
            double **d = da, **dn = db;
#pragma GCC unroll 4
            EACH {
                const double *y = act[u] + aoff[NL] * 4;
                const double *t0 = Y + ord[u][0][j] * ldy, *t1 = Y + ord[u][1][j] * ldy;
                const double *t2 = Y + ord[u][2][j] * ldy, *t3 = Y + ord[u][3][j] * ldy;
                __m256d pl = _mm256_setzero_pd();
#pragma GCC unroll 4
                for (int64_t o = 0; o < nout; o++) {
                    __m256d yv = LD(y + o * 4);
                    __m256d diff = _mm256_sub_pd(yv, _mm256_set_pd(t3[o], t2[o], t1[o], t0[o]));
                    if (masked) {
                        pl = _mm256_fmadd_pd(diff, diff, pl);
                        const __m256d dm = _mm256_and_pd(diff, live[u]);
                        lsum[u] = _mm256_fmadd_pd(dm, dm, lsum[u]);
                    } else {
                        lsum[u] = _mm256_fmadd_pd(diff, diff, lsum[u]);
                    }
                    ST(d[u] + o * 4, _mm256_mul_pd(_mm256_mul_pd(_mm256_mul_pd(diff, scale[u]), yv),
                                                   _mm256_sub_pd(one, yv)));
                }
                if (masked && plosses) {
                    double v[4];
                    _mm256_storeu_pd(v, _mm256_div_pd(pl, _mm256_set1_pd((double)nout)));
                    for (int q = 0; q < 4; q++)
                        if (j < cnt[u][q]) plosses[((g + u) * 4 + q) * m + j] = v[q];
                }
            }
            /* backward, layer by layer: deltas of the layer below (from the weights before their
               update), then the layer's update (B = 1) or gradient accumulation (B > 1) */
#pragma GCC unroll 8
            for (int l = NL - 1; l >= 0; l--) {
                const int64_t ni_ = S[l], no = S[l + 1];
                if (l > 0) {
#pragma GCC unroll 4
                    for (int64_t i = 0; i < ni_; i++) {
                        __m256d acc[NI];
#pragma GCC unroll 4
                        EACH acc[u] = _mm256_setzero_pd();
#pragma GCC unroll 4
                        for (int64_t o = 0; o < no; o++) {
#pragma GCC unroll 4
                            EACH acc[u] = _mm256_fmadd_pd(LD(w[u] + (woff[l] + o * ni_ + i) * 4),
                                                          LD(d[u] + o * 4), acc[u]);
                        }
#pragma GCC unroll 4
                        EACH {
                            __m256d a = LD(act[u] + (aoff[l] + i) * 4);
                            ST(dn[u] + i * 4, _mm256_mul_pd(_mm256_mul_pd(acc[u], a), _mm256_sub_pd(one, a)));
                        }
                    }
                }
#pragma GCC unroll 4
                for (int64_t o = 0; o < no; o++) {
#pragma GCC unroll 4
                    EACH {
                        const __m256d dv = LD(d[u] + o * 4);
                        const double *ain = act[u] + aoff[l] * 4;
                        if (B == 1) {
                            /* buf = mom * buf + g; p -= lr * buf (torch.optim.SGD) */
                            double *wr = w[u] + (woff[l] + o * ni_) * 4;
                            double *mr = mb[u] + (woff[l] + o * ni_) * 4;
#pragma GCC unroll 4
                            for (int64_t i = 0; i < ni_; i++) {
                                const __m256d m0 = LD(mr + i * 4), w0 = LD(wr + i * 4);
                                __m256d bv = _mm256_fmadd_pd(vmom, m0, _mm256_mul_pd(dv, LD(ain + i * 4)));
                                __m256d wv = _mm256_fnmadd_pd(vlr, bv, w0);
                                if (masked) {  /* a lane past its count keeps its weights and momenta */
                                    bv = _mm256_blendv_pd(m0, bv, live[u]);
                                    wv = _mm256_blendv_pd(w0, wv, live[u]);
                                }
                                ST(mr + i * 4, bv);
                                ST(wr + i * 4, wv);
                            }
                            double *pb = w[u] + (boff[l] + o) * 4, *pm = mb[u] + (boff[l] + o) * 4;
                            const __m256d m0 = LD(pm), w0 = LD(pb);
                            __m256d bv = _mm256_fmadd_pd(vmom, m0, dv);
                            __m256d wv = _mm256_fnmadd_pd(vlr, bv, w0);
                            if (masked) {
                                bv = _mm256_blendv_pd(m0, bv, live[u]);
                                wv = _mm256_blendv_pd(w0, wv, live[u]);
                            }
                            ST(pm, bv);
                            ST(pb, wv);
                        } else {
                            double *gr = G[u] + (woff[l] + o * ni_) * 4, *pgb = G[u] + (boff[l] + o) * 4;
#pragma GCC unroll 4
                            for (int64_t i = 0; i < ni_; i++) {
                                __m256d gv = _mm256_fmadd_pd(dv, LD(ain + i * 4), LD(gr + i * 4));
                                if (masked) gv = _mm256_blendv_pd(LD(gr + i * 4), gv, live[u]);
                                ST(gr + i * 4, gv);
                            }
                            __m256d gb = _mm256_add_pd(LD(pgb), dv);
                            if (masked) gb = _mm256_blendv_pd(LD(pgb), gb, live[u]);
                            ST(pgb, gb);
                        }
                    }
                }
                double **tmp = d; d = dn; dn = tmp;
            }
        }
        if (B > 1) {  /* the mini-batch's update from the summed gradient (masked: lanes with patterns in it) */
#pragma GCC unroll 4
            EACH for (int64_t p = 0; p < P_TOTAL; p++) {
                const __m256d m0 = LD(mb[u] + p * 4), w0 = LD(w[u] + p * 4);
                __m256d bv = _mm256_fmadd_pd(vmom, m0, LD(G[u] + p * 4));
                __m256d wv = _mm256_fnmadd_pd(vlr, bv, w0);
                if (masked) {
                    bv = _mm256_blendv_pd(m0, bv, blive[u]);
                    wv = _mm256_blendv_pd(w0, wv, blive[u]);
                }
                ST(mb[u] + p * 4, bv);
                ST(w[u] + p * 4, wv);
            }
        }
    }
#pragma GCC unroll 4
    EACH {
        double ls[4];
        _mm256_storeu_pd(ls, lsum[u]);
        for (int k = 0; k < 4; k++) loss[(g + u) * 4 + k] = ls[k] / (double)nout;
    }
#undef EACH
}

/* One epoch for groups [g0, g1): W, M [G][P_TOTAL][4] updated in place; order [G*4][m] pattern indices;
   loss[g*4 + k] gets lane k's summed per-pattern loss. Pattern r's inputs are X[r * ldx ..], its targets
   Y[r * ldy ..]: ldx = S[0], ldy = S[NL] for separate arrays, or both the row length of one array holding
   each pattern's inputs and targets side by side (selpres/native/staging.py). counts [G*4], wts [G*4][m],
   plosses [G*4][m]: a pruned epoch (see train_groups), each NULL when not used; all three NULL is the usual
   epoch. Returns 0, -1 (out of memory) or -3 (the caller's topology is not the one compiled in). */
int selpres_train(int nl, const int64_t *sizes, int64_t g0, int64_t g1, int64_t P,
                  double *W, double *M, const double *X, const double *Y,
                  const int64_t *order, int64_t m, int64_t B, double lr, double mom, double *loss,
                  int64_t ldx, int64_t ldy, const int64_t *counts, const double *wts, double *plosses)
{
    if (nl != NL || P != P_TOTAL) return -3;
    for (int l = 0; l <= NL; l++) if (sizes[l] != S[l]) return -3;
    if (ldx < S[0] || ldy < S[NL]) return -3;
    double *work = (double *)aligned_alloc(32, (size_t)NI * WORK_DOUBLES * 8);
    double *Gb = B > 1 ? (double *)aligned_alloc(32, (size_t)NI * P_TOTAL * 32) : NULL;
    if (!work || (B > 1 && !Gb)) {
        free(work);
        free(Gb);
        return -1;
    }
    int64_t g = g0;
#define GROUPS(masked)                                                                                      \
    for (; g + NI <= g1; g += NI)                                                                           \
        train_groups(NI, masked, g, W, M, Gb, work, X, Y, order, m, B, lr, mom, loss, ldx, ldy, counts, wts, \
                     plosses);                                                                              \
    for (; g < g1; g++)                                                                                     \
        train_groups(1, masked, g, W, M, Gb, work, X, Y, order, m, B, lr, mom, loss, ldx, ldy, counts, wts, plosses);
    if (counts || wts || plosses) {
        GROUPS(1)
    } else {
        GROUPS(0)
    }
#undef GROUPS
    free(work);
    free(Gb);
    return 0;
}

/* ------------------------------------------------------------------------------------------------
   Forward passes only (evaluation): the same layout, every replica sees the same inputs. Patterns are
   independent, so NPAT of them are advanced together: one weight load feeds NPAT FMAs and the NPAT
   sigmoid chains overlap. The loop runs group by group so that a group's weights stay in L1 while all
   patterns stream past. The code is in eval.h, written once for VL lanes and instantiated here for 4
   (ymm: one group) and, where the compiler targets AVX-512F, for 8 (zmm: two groups g, g+1 side by
   side, their weights interleaved once per call into [P_TOTAL][8], see pack_pair); a chunk's leftover
   odd group runs at 4 lanes. At 4 lanes evaluation is bound by the FMA ports (~47 cycles a replica's
   forward pass at 6-13-2), and zmm FMAs do ~1.7x the work per cycle on AVX-512 cores; measured, 8 lanes
   take 1.3x less time (~37 cycles): the sigmoid's division, whose throughput per lane is the same at
   either width (16 cycles a zmm, 8 a ymm), then bounds it (~30 cycles of divider a replica-forward at
   6-13-2; with a multiplication in its place, a throwaway test, 8 lanes took ~29 cycles). Lanes are
   independent and every lane sees the same operations in the same order at either width (exp8 is exp4
   operation for operation), so numbers are bitwise the same with or without AVX-512, however groups
   are paired or split among threads. */
#define NPAT 8

#define VL 4
#define VEC __m256d
#define VOP(op) _mm256_##op
#define VSIGMOID sigmoid4
#define VF(name) name##_4
#include "eval.h"

#ifdef __AVX512F__
#define EVAL_LANES 8

/* exp4 for 8 lanes, operation for operation: the same clamp (operand order keeps NaN), the same rounding
   (roundscale with scale 0 is round_pd), the same Cody-Waite and Horner fnmadd/fmadd chain and scaling.
   AVX-512F only (the sign flip in sigmoid8 is an integer xor: xor_pd would need AVX-512DQ). */
static inline __m512d exp8(__m512d x) {
    x = _mm512_min_pd(_mm512_set1_pd(708.0), x);   /* operand order keeps NaN */
    x = _mm512_max_pd(_mm512_set1_pd(-708.0), x);
    __m512d n = _mm512_roundscale_pd(_mm512_mul_pd(x, _mm512_set1_pd(1.4426950408889634)),
                                     _MM_FROUND_TO_NEAREST_INT | _MM_FROUND_NO_EXC);
    __m512d r = _mm512_fnmadd_pd(n, _mm512_set1_pd(6.93147180369123816490e-01), x);
    r = _mm512_fnmadd_pd(n, _mm512_set1_pd(1.90821492927058770002e-10), r);
    __m512d p = _mm512_set1_pd(1.0 / 6227020800.0);
    p = _mm512_fmadd_pd(p, r, _mm512_set1_pd(1.0 / 479001600.0));
    p = _mm512_fmadd_pd(p, r, _mm512_set1_pd(1.0 / 39916800.0));
    p = _mm512_fmadd_pd(p, r, _mm512_set1_pd(1.0 / 3628800.0));
    p = _mm512_fmadd_pd(p, r, _mm512_set1_pd(1.0 / 362880.0));
    p = _mm512_fmadd_pd(p, r, _mm512_set1_pd(1.0 / 40320.0));
    p = _mm512_fmadd_pd(p, r, _mm512_set1_pd(1.0 / 5040.0));
    p = _mm512_fmadd_pd(p, r, _mm512_set1_pd(1.0 / 720.0));
    p = _mm512_fmadd_pd(p, r, _mm512_set1_pd(1.0 / 120.0));
    p = _mm512_fmadd_pd(p, r, _mm512_set1_pd(1.0 / 24.0));
    p = _mm512_fmadd_pd(p, r, _mm512_set1_pd(1.0 / 6.0));
    p = _mm512_fmadd_pd(p, r, _mm512_set1_pd(0.5));
    p = _mm512_fmadd_pd(p, r, _mm512_set1_pd(1.0));
    p = _mm512_fmadd_pd(p, r, _mm512_set1_pd(1.0));
    __m512d t = _mm512_add_pd(n, _mm512_set1_pd(6755399441055744.0));   /* 1.5 * 2^52: n in the low bits */
    __m512i e = _mm512_slli_epi64(_mm512_add_epi64(_mm512_castpd_si512(t), _mm512_set1_epi64(1023)), 52);
    return _mm512_mul_pd(p, _mm512_castsi512_pd(e));
}

static inline __m512d sigmoid8(__m512d z) {
    const __m512d one = _mm512_set1_pd(1.0);
    const __m512i sign = _mm512_set1_epi64(INT64_MIN);  /* the bits of -0.0 */
    const __m512d minus_z = _mm512_castsi512_pd(_mm512_xor_si512(_mm512_castpd_si512(z), sign));
    return _mm512_div_pd(one, _mm512_add_pd(one, exp8(minus_z)));
}

#define VL 8
#define VEC __m512d
#define VOP(op) _mm512_##op
#define VSIGMOID sigmoid8
#define VF(name) name##_8
#include "eval.h"

/* Groups g and g+1 of W [G][P_TOTAL][4] as one [P_TOTAL][8] block (lanes 0-3: group g, 4-7: group g+1),
   the layout forward_act_8 reads: one zmm load per weight, not two loads and an insert every time. */
static void pack_pair(const double *W, int64_t g, double *w8)
{
    const double *a = W + g * P_TOTAL * 4, *b = a + P_TOTAL * 4;
    for (int64_t p = 0; p < P_TOTAL; p++)
        _mm512_storeu_pd(w8 + p * 8,
                         _mm512_insertf64x4(_mm512_castpd256_pd512(LD(a + p * 4)), LD(b + p * 4), 1));
}
#else
#define EVAL_LANES 4
#endif

/* The vector width evaluation runs at in this build (8: AVX-512F pairs of groups; 4: AVX2), so the caller
   can record what ran. */
int selpres_eval_lanes(void) { return EVAL_LANES; }

/* Work arrays of one evaluation call: NPAT patterns' activations and accumulators at the widest width,
   then (8 lanes) one packed pair of groups. 64-byte aligned, sizes multiples of 64 (aligned_alloc). */
static double *eval_work(void)
{
    size_t n = (size_t)NPAT * (TOT_UNITS + MAXW) * EVAL_LANES + (EVAL_LANES == 8 ? P_TOTAL * 8 : 0);
    return (double *)aligned_alloc(64, n * sizeof(double));
}

/* Outputs of the replicas of groups [g0, g1) on patterns [n0, n1) of X [N][S[0]]: out [G*4][N][S[NL]].
   W as in selpres_train. Returns 0, -1 (out of memory) or -3 (not the topology compiled in). */
int selpres_forward(int nl, const int64_t *sizes, int64_t g0, int64_t g1, int64_t n0, int64_t n1, int64_t P,
                    const double *W, const double *X, int64_t N, double *out)
{
    if (nl != NL || P != P_TOTAL) return -3;
    for (int l = 0; l <= NL; l++) if (sizes[l] != S[l]) return -3;
    double *work = eval_work();
    if (!work) return -1;
    int64_t g = g0;
#if EVAL_LANES == 8
    double *w8 = work + NPAT * (TOT_UNITS + MAXW) * 8;
    for (; g + 2 <= g1; g += 2) {
        pack_pair(W, g, w8);
        forward_range_8(w8, work, X, n0, n1, N, g * 4, out);
    }
#endif
    for (; g < g1; g++) forward_range_4(W + g * P_TOTAL * 4, work, X, n0, n1, N, g * 4, out);
    free(work);
    return 0;
}


/* ------------------------------------------------------------------------------------------------
   Scoring without outputs (evaluation): per replica and output, the sum over patterns of
   (output - target)^2, accumulated inside the forward pass, so no [R][N][out] array is written.
   Patterns are cut into blocks of bn (fixed by the caller, not by the thread count); sums gets one
   partial sum per block, sums[b][g*4 + k][o] for group g of G, and the caller adds the blocks in order.
   Within a block, pattern n adds into accumulator n mod NPAT (the leftover patterns into accumulator
   0), and the accumulators are added 0, 1, ..., NPAT-1 (sqerr_blocks in eval.h): the result depends on
   bn only, never on how groups or blocks are spread over threads, nor on the vector width. Y [N][S[NL]]
   in the network's (scaled) units. */
int selpres_sqerr(int nl, const int64_t *sizes, int64_t g0, int64_t g1, int64_t b0, int64_t b1, int64_t bn,
                  int64_t P, const double *W, const double *X, const double *Y, int64_t N, int64_t G,
                  double *sums)
{
    if (nl != NL || P != P_TOTAL || bn < 1) return -3;
    for (int l = 0; l <= NL; l++) if (sizes[l] != S[l]) return -3;
    double *work = eval_work();
    if (!work) return -1;
    int64_t g = g0;
#if EVAL_LANES == 8
    double *w8 = work + NPAT * (TOT_UNITS + MAXW) * 8;
    for (; g + 2 <= g1; g += 2) {
        pack_pair(W, g, w8);
        sqerr_blocks_8(w8, work, X, Y, N, b0, b1, bn, G * 4, g * 4, sums);
    }
#endif
    for (; g < g1; g++) sqerr_blocks_4(W + g * P_TOTAL * 4, work, X, Y, N, b0, b1, bn, G * 4, g * 4, sums);
    free(work);
    return 0;
}

/* finite[g*4 + k] = 1 if every parameter of lane k of group g (of groups [0, G)) is finite, else 0.
   x * 0 is 0 for a finite x and NaN for an infinite or NaN one, so a lane's sum of them is 0 exactly when
   all its parameters are finite, whatever their size (no overflow, unlike a sum of the weights). */
int selpres_finite(int64_t G, int64_t P, const double *W, int8_t *finite)
{
    if (P != P_TOTAL) return -3;
    const __m256d zero = _mm256_setzero_pd();
    for (int64_t g = 0; g < G; g++) {
        const double *w = W + g * P_TOTAL * 4;
        __m256d a0 = zero, a1 = zero;
        int64_t p = 0;
        for (; p + 2 <= P_TOTAL; p += 2) {
            a0 = _mm256_fmadd_pd(LD(w + p * 4), zero, a0);
            a1 = _mm256_fmadd_pd(LD(w + p * 4 + 4), zero, a1);
        }
        if (p < P_TOTAL) a0 = _mm256_fmadd_pd(LD(w + p * 4), zero, a0);
        double v[4];
        _mm256_storeu_pd(v, _mm256_add_pd(a0, a1));
        for (int k = 0; k < 4; k++) finite[g * 4 + k] = v[k] == 0.0;
    }
    return 0;
}
