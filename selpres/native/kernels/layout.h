/* layer_offsets: where each layer's weights, biases and activations start in a replica's packed parameters
 * and activations, shared by sgd.c (online SGD, its evaluation in eval.h) and minibatch.c. Needs NL and the
 * layer widths S[NL + 1] defined before it is included. */
#ifndef SELPRES_LAYOUT_H
#define SELPRES_LAYOUT_H

/* Where layer l's weights (woff) and biases (boff) start among a replica's parameters, and where the
   activations of layer l's units start (aoff; layer 0 = the inputs). */
static inline void layer_offsets(int64_t *woff, int64_t *boff, int64_t *aoff)
{
    int64_t off = 0, tot = 0;
    for (int l = 0; l < NL; l++) {
        woff[l] = off; off += S[l + 1] * S[l]; boff[l] = off; off += S[l + 1];
    }
    for (int l = 0; l <= NL; l++) { aoff[l] = tot; tot += S[l]; }
}

#endif
