"""What a ``SelectivePresentation`` has handed out: its passes over an epoch, where a resumed epoch starts, the count
of presentations, and the warnings that say why an epoch was not presented as the schedule plans it.

Split from ``selpres.presentation.sampler`` (the host of ``Handout``, which supplies ``epoch``, ``num_epochs``,
``num_samples``, ``rank_indices`` and ``_plan``). A pass is the list of this rank's indices for the epoch, the list
iterator the loop consumes (its length hint says how far the loop got, at no cost per index) and where it started.
``state_dict`` is the epoch, the position within it and the count: what a fresh sampler of the same arguments cannot
recompute (the shuffles are a function of seed and epoch), in the form torchdata's ``StatefulDataLoader`` saves.
"""

from __future__ import annotations

import sys
import warnings
import weakref

LIGHTNING = ("lightning", "pytorch_lightning")  # module prefixes of a Trainer (lightning_fabric included)


class SelectivePresentationWarning(UserWarning):
    """A loop that presents something other than the schedule (an epoch repeated, or cut short)."""


def _last_epoch_stopped(box: dict) -> None:
    """At exit (or when the sampler goes): a last epoch the loop left unfinished, which no set_epoch can report."""
    p = box.pop("pass", None)
    if p is None or p[1].__length_hint__() == 0:
        return
    done, share = p[2] - p[1].__length_hint__(), p[2]
    cause = box.get("cause") or "the loop stopped before the end of the schedule"
    warnings.warn(
        f"epoch {box['epoch']}, the schedule's last, presented {done} of its {share} patterns: {cause} "
        f"(sampler.presentations counts the {(box['base'] + done) * box['world']:,} handed out)",
        SelectivePresentationWarning,
        stacklevel=2,
    )


class Handout:
    """The bookkeeping half of ``SelectivePresentation`` (a mixin): passes, position, count, resume, warnings."""

    stop_cause: str | None = None  # why an epoch may end early (set by the Lightning callback), named in warnings

    def _begin_handout(self) -> None:
        self._base = 0  # this rank's presentations before the current pass (earlier epochs, earlier passes)
        self._pass: list | None = None  # [indices from start, their iterator, the epoch's share, start]
        self._resume_at = 0  # where the next pass of this epoch starts (a loaded state's position)
        self._resumed = False  # the position came from load_state_dict, mid-epoch
        self._chosen = False  # set_epoch chose this epoch (a state loaded afterwards must agree)
        self._again = False  # set_epoch(this epoch) was called after its pass began
        self._another_pass = False  # the loop announced a fresh pass of this epoch (expect_new_pass)
        self._warned: set[str] = set()
        self._batches_checked: set = set()
        self._lightning = False  # driven by a SelectivePresentationCallback
        self._last = {"pass": None}  # the last epoch's pass, checked when the sampler goes
        self._finalizer = None

    def __getstate__(self) -> dict:
        state = self.__dict__.copy()
        state["_finalizer"], state["_last"] = None, {"pass": None}  # a copy reports nothing on the original's behalf
        return state

    # ------------------------------------------------------------------------------------ position and count

    def _position(self) -> int:
        """This rank's indices of the current epoch handed out so far (by its current pass)."""
        p = self._pass
        return self._resume_at if p is None else p[2] - p[1].__length_hint__()

    @property
    def rank_presentations(self) -> int:
        """This rank's presentations so far: every index it handed to the loop (passes cut short, repeated passes
        and a resumed run's earlier ones, from its state, included)."""
        return self._base + self._position()

    @property
    def presentations(self) -> int:
        """All ranks' presentations so far: T / t, the cost axis (ranks present equal shares, padding included)."""
        return self.rank_presentations * self.num_replicas

    def state_dict(self) -> dict:
        """This rank's place in the schedule: ``epoch``, ``position`` (indices of it handed out) and
        ``rank_presentations``; torchdata's ``StatefulDataLoader`` saves it with its own, or keep it beside yours."""
        return {"epoch": self.epoch, "position": self._position(), "rank_presentations": self.rank_presentations}

    def load_state_dict(self, state: dict) -> None:
        """Continue where ``state`` (``state_dict()`` of a sampler of the same arguments) stopped: the next pass
        starts at its position. ``set_epoch`` with the saved epoch keeps it; a StatefulDataLoader loads the state
        when iterated, after the loop's ``set_epoch``, which must then name the same epoch (or a later one when the
        saved epoch was complete)."""
        if not isinstance(state, dict) or not {"epoch", "position", "rank_presentations"} <= set(state):
            raise ValueError(f"state={state!r}: expected a SelectivePresentation state_dict()")
        from selpres.presentation.arguments import _whole

        e = _whole("state['epoch']", state["epoch"], 0)
        if e >= self.num_epochs:
            raise ValueError(f"state['epoch']={e}: this sampler's schedule has {self.num_epochs} epochs")
        share = self._share(self._plan[e].presentations, self.num_replicas)
        k = _whole("state['position']", state["position"], 0)
        if k > share:
            raise ValueError(f"state['position']={k}: epoch {e} hands out {share} indices on this rank")
        count = _whole("state['rank_presentations']", state["rank_presentations"], k)
        self._pass, self._another_pass = None, False
        if self._chosen and e != self.epoch:
            if k < share or e > self.epoch:
                raise ValueError(
                    f"the loader's state is at epoch {e} (pattern {k} of {share}) but set_epoch({self.epoch}) was "
                    f"called: resume the loop at the saved epoch, for epoch in range({e}, sampler.num_epochs)"
                )
            self._base, self._resume_at, self._resumed = count, 0, False  # that epoch was complete
            return
        self.epoch, self._base, self._resume_at, self._resumed = e, count - k, k, 0 < k < share

    # ------------------------------------------------------------------------------------ passes

    def _move_to(self, epoch: int) -> None:
        """set_epoch's bookkeeping: count the epoch left, say if it was cut, and let an untouched iterator (made
        before set_epoch, as Lightning makes it) present the new epoch."""
        if epoch == self.epoch:
            self._again = self._pass is not None
            self._chosen = True
            return
        if self._pass is None and not self._resume_at:  # nothing handed out (the CLI's samplers): only the epoch
            self.epoch, self._chosen, self._another_pass, self._resumed = epoch, True, False, False
            return
        done, p = self._position(), self._pass
        share = p[2] if p is not None else self.num_samples
        if 0 < done < share:
            self._warn_cut(epoch, done, share)
        self._base += done
        untouched = p is not None and len(p[0]) > 0 and p[1].__length_hint__() == len(p[0])
        self.epoch, self._pass, self._resume_at, self._resumed = epoch, None, 0, False
        self._another_pass = self._again = False
        self._last["pass"] = None
        self._chosen = True
        if untouched:
            new = self.rank_indices().tolist()
            p[0][:] = new  # the list iterator reads the list in place
            p[2], p[3] = len(new), 0
            self._pass = p
            self._watch_last()

    def __iter__(self):
        p, start = self._pass, self._resume_at
        if p is not None:
            consumed = p[2] - p[1].__length_hint__() - p[3]
            if self._another_pass or consumed == 0:  # abandoned (a prefetching iterator) or never used: replaced
                start = p[3]
            else:
                self._base += self._position()
                start = 0
                self._warn_repeat()
        self._another_pass = self._again = False
        self._resume_at = 0
        indices = self.rank_indices().tolist()
        self._check_batches(sys._getframe(1))
        rest = indices[start:] if start else indices
        self._pass = [rest, iter(rest), len(indices), start]  # a plain list iterator: its length hint is free
        self._watch_last()
        return self._pass[1]

    def expect_new_pass(self) -> None:
        """The loop is about to start a fresh pass over this epoch after an abandoned one (Lightning re-creates
        its iterator after a worker prefetch): that pass is neither a repeat nor counted."""
        self._another_pass = True

    # ------------------------------------------------------------------------------------ checks and warnings

    def _check_batches(self, frame) -> None:
        """A ``BatchSampler(drop_last=True)`` (a DataLoader's) larger than a stage's share presents nothing of it."""
        if frame is None or frame.f_code.co_name not in ("__iter__", "__init__"):  # f_locals of any other frame
            return  # would keep a snapshot of its variables alive (this sampler among them)
        local = frame.f_locals
        owner = local.get("self")  # torch's BatchSampler.__iter__, or torchdata's iterator while it is made
        if getattr(owner, "sampler", None) is not self:
            return
        bs, world = getattr(owner, "batch_size", local.get("batch_size")), self.num_replicas
        if getattr(owner, "drop_last", local.get("drop_last")) is not True:
            return
        if not isinstance(bs, int) or (bs, world) in self._batches_checked:
            return
        for ep in self._plan:
            share = self._share(ep.presentations, world)
            if share < bs:
                size = self.schedule.stages[ep.stage].size
                per_rank = f" ({share} per rank of {world})" if world > 1 else ""
                raise ValueError(
                    f"A_{ep.stage + 1} presents {ep.presentations} patterns an epoch{per_rank} (n_{ep.stage + 1} = "
                    f"{size}), fewer than DataLoader(batch_size={bs}, drop_last=True) needs for one batch: its epochs "
                    f"would present nothing. Use drop_last=False or batch_size <= {share}"
                )
        self._batches_checked.add((bs, world))

    def _warn_repeat(self) -> None:
        e = self.epoch
        if self._again:
            self._warn(
                "repeat-set",
                f"epoch {e} is presented again: set_epoch({e}) was called again after its pass, so the same "
                f"patterns come in the same order. Call set_epoch with the next epoch: for epoch in "
                "range(sampler.num_epochs): sampler.set_epoch(epoch); ...",
                stacklevel=4,
            )
        else:
            self._warn(
                "repeat",
                f"epoch {e} is presented again: without set_epoch every pass presents the same training set "
                f"A_{self.stage + 1} in the same order, for ever. Call sampler.set_epoch(epoch) before each epoch: "
                "for epoch in range(sampler.num_epochs): sampler.set_epoch(epoch); ...",
                stacklevel=4,
            )

    def _warn_cut(self, following: int, done: int, share: int) -> None:
        e = self.epoch
        if self._resumed and self._pass is None:
            self._warn(
                "cut-resume",
                f"epoch {e} was resumed at pattern {done} of its {share} (load_state_dict) but set_epoch({following}) "
                f"came before the rest was presented: resume the loop at the saved epoch, for epoch in "
                f"range({e}, sampler.num_epochs)",
                stacklevel=6,
            )
        elif self.stop_cause:
            self._warn("cut", f"epoch {e} presented {done} of its {share} patterns: {self.stop_cause}", stacklevel=6)
        else:
            self._warn(
                "cut",
                f"epoch {e} presented {done} of its {share} patterns before set_epoch({following}): the loop stopped "
                "early. A loop that counts an epoch's batches once (Lightning does) cuts every larger "
                "stage: with Lightning add selpres.presentation.lightning.SelectivePresentationCallback(sampler)",
                stacklevel=6,  # the caller of set_epoch
            )

    def _watch_last(self) -> None:
        """The schedule's last epoch has no set_epoch after it: its pass is checked when the sampler goes."""
        if self.epoch != self.num_epochs - 1:
            return
        self._last.update({"pass": self._pass, "epoch": self.epoch, "base": self._base, "world": self.num_replicas})
        if self.stop_cause:
            self._last["cause"] = self.stop_cause
        if self._finalizer is None:
            self._finalizer = weakref.finalize(self, _last_epoch_stopped, self._last)

    def finish(self, cause: str | None = None) -> None:
        """Say now (not at exit) if the last epoch was left unfinished, naming ``cause``."""
        if cause:
            self._last["cause"] = cause
        _last_epoch_stopped(self._last)

    def _warn(self, what: str, message: str, stacklevel: int = 3) -> None:
        if what not in self._warned:  # once per sampler and kind
            self._warned.add(what)
            warnings.warn(message, SelectivePresentationWarning, stacklevel=stacklevel)
