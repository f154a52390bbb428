"""Selective presentation in a Lightning ``Trainer``: one callback (only this module imports Lightning, an extra:
``pip install 'selpres[lightning]'``).

    sampler = SelectivePresentation(X, sizes=[0.05, 0.1, 0.4, 0.8, 1.0], epochs=[30] * 5, seed=0)
    loader = DataLoader(dataset, batch_size=32, sampler=sampler)
    Trainer(callbacks=[SelectivePresentationCallback(sampler)]).fit(model, loader)

Why a callback: Lightning counts an epoch's batches once, from the first ``len(dataloader)``, and never again,
so every later (larger) stage would be cut to A1's size; and it sets a sampler's epoch only *after* counting.
The callback (1) turns on ``reload_dataloaders_every_n_epochs=1`` so Lightning recounts every epoch, (2) sets the
sampler's next epoch at the end of each epoch, before Lightning recounts, (3) caps ``max_epochs`` at the
schedule's ``num_epochs`` (Lightning's default is 1000), (4) checks at each epoch start that Lightning's
batch count is the stage's, so a mismatch fails loudly instead of training on the wrong patterns, and (5) keeps the
sampler's place in Lightning's checkpoints (its ``state_dict``: the epoch, the position Lightning's finished batches
reached, the count), so a mid-epoch checkpoint (``ModelCheckpoint(every_n_train_steps=…)``) resumes exactly, with a
plain ``DataLoader`` (any ``num_workers``) or torchdata's ``StatefulDataLoader``. Under ``strategy="ddp"`` nothing
more is needed: the sampler is a ``DistributedSampler`` (Lightning leaves it unwrapped, so no fixed-size wrapper
asserts at a stage change) and reads rank and world from the process group; the ranks' places are equal.
"""

from __future__ import annotations

from selpres.presentation.sampler import SelectivePresentation

try:
    import lightning.pytorch as pl
    from lightning.pytorch.utilities import rank_zero_info, rank_zero_warn
except ImportError as exc:  # pragma: no cover - the extra is installed in the set-up
    raise ImportError(
        f"selpres.presentation.lightning needs Lightning: pip install 'selpres[lightning]' ({exc})"
    ) from None


def _loaders(obj):
    """The DataLoaders in whatever Lightning holds as the train dataloader(s) (one, or a collection)."""
    if isinstance(obj, dict):
        obj = list(obj.values())
    if isinstance(obj, (list, tuple)):
        return [d for o in obj for d in _loaders(o)]
    return [obj]


def _samplers(loader):
    batch_sampler = getattr(loader, "batch_sampler", None)
    return {id(s): s for s in (getattr(loader, "sampler", None), getattr(batch_sampler, "sampler", None))}


class SelectivePresentationCallback(pl.Callback):
    """Makes a Lightning ``Trainer`` (1 device or DDP) present exactly each stage's training set every epoch."""

    def __init__(self, sampler: SelectivePresentation):
        if not isinstance(sampler, SelectivePresentation):
            raise TypeError(f"sampler: expected the loader's SelectivePresentation, got {type(sampler).__name__}")
        self.sampler = sampler
        sampler._lightning = True  # Lightning may set its epochs (without a callback the sampler refuses)
        self._trainer = None

    def setup(self, trainer: pl.Trainer, pl_module: pl.LightningModule, stage: str) -> None:
        if stage != "fit":
            return
        self._trainer = trainer
        if trainer.limit_train_batches != 1.0:
            self.sampler.stop_cause = (
                f"Trainer(limit_train_batches={trainer.limit_train_batches}) ends every epoch early, so each stage's "
                "training set is presented in part (sampler.presentations counts what was)"
            )
        every = trainer.reload_dataloaders_every_n_epochs
        if every == 0:
            trainer.reload_dataloaders_every_n_epochs = 1
            rank_zero_info("SelectivePresentationCallback: reload_dataloaders_every_n_epochs=1 (recount every epoch)")
        elif every != 1:
            raise ValueError(
                f"reload_dataloaders_every_n_epochs={every}: expected 0 or 1 with SelectivePresentationCallback "
                "(a stage's batches must be counted in every epoch)"
            )
        E, loop = self.sampler.num_epochs, trainer.fit_loop
        if loop.max_epochs is None or loop.max_epochs == -1 or loop.max_epochs > E:
            rank_zero_info(f"SelectivePresentationCallback: max_epochs={E}, the schedule's epochs")
            loop.max_epochs = E
        elif loop.max_epochs < E:
            rank_zero_warn(
                f"Trainer(max_epochs={loop.max_epochs}) stops before the schedule's {E} epochs: stages after "
                f"epoch {loop.max_epochs} are never presented"
            )

    def state_dict(self) -> dict:
        """The sampler's place as Lightning's finished batches left it (a worker's prefetch not counted), a finished
        epoch as the start of the next; the same on every rank (equal shares)."""
        s, t = self.sampler, self._trainer
        state = s.state_dict()
        share = len(s)
        if t is not None and s.epoch == t.current_epoch:
            loaders = [d for d in _loaders(t.train_dataloader) if id(s) in _samplers(d)]
            size = getattr(loaders[0], "batch_size", None) if loaders else None
            if isinstance(size, int):
                done = min(t.fit_loop.epoch_loop.batch_progress.current.processed * size, share)
                state["rank_presentations"] -= state["position"] - done
                state["position"] = done
        if state["position"] == share and state["epoch"] + 1 < s.num_epochs:
            state["epoch"], state["position"] = state["epoch"] + 1, 0
        return state

    def load_state_dict(self, state_dict: dict) -> None:
        """A resumed fit continues at the saved place, mid-epoch included (Lightning then runs the epoch's remaining
        batches, which are exactly the rest of its order)."""
        if state_dict:
            self.sampler.load_state_dict(state_dict)
            self.sampler.set_epoch(state_dict["epoch"])  # the loop's epoch (a loader's own state must agree)
            if state_dict["position"]:
                rank_zero_info(
                    f"SelectivePresentationCallback: epoch {state_dict['epoch']} resumes at pattern "
                    f"{state_dict['position']} of {len(self.sampler)} (exact: Lightning's 'not resumable' warning "
                    "does not apply to the sampler's order)"
                )

    def on_load_checkpoint(self, trainer: pl.Trainer, pl_module: pl.LightningModule, checkpoint: dict) -> None:
        """A resumed fit from a checkpoint without the callback's state: the sampler starts at the epoch Lightning
        resumes, before Lightning counts batches."""
        batches = checkpoint.get("loops", {}).get("fit_loop", {}).get("epoch_loop.batch_progress", {})
        current = batches.get("current", {})
        if batches.get("is_last_batch") and current.get("completed") == current.get("processed", 0) - 1:
            # saved at an epoch's last batch: Lightning resumes the next epoch, but checks the saved epoch's finished
            # batches against the *next* epoch's count, and a larger stage would run only the difference; finished
            # batches beyond any count make it start that epoch at its first batch, as an end-of-epoch save does
            current.update(ready=1 << 30, started=1 << 30, processed=1 << 30, completed=(1 << 30) - 1)
        if checkpoint.get("callbacks", {}).get(self.state_key):
            return  # load_state_dict restores the exact place
        progress = checkpoint.get("loops", {}).get("fit_loop", {}).get("epoch_progress", {}).get("current", {})
        epoch = progress.get("processed")
        if isinstance(epoch, int) and 0 <= epoch < self.sampler.num_epochs:
            self.sampler.set_epoch(epoch)

    def on_train_start(self, trainer: pl.Trainer, pl_module: pl.LightningModule) -> None:
        """A resumed fit that moved to the next epoch recounts (a second iterator) after its first one prefetched:
        that first pass is abandoned, not repeated."""
        self.sampler.expect_new_pass()

    def on_train_epoch_start(self, trainer: pl.Trainer, pl_module: pl.LightningModule) -> None:
        s = self.sampler
        loaders = [d for d in _loaders(trainer.train_dataloader) if id(s) in _samplers(d)]
        if not loaders:
            raise RuntimeError(
                "SelectivePresentationCallback: the train dataloader does not use the callback's sampler; build "
                "the DataLoader with sampler=<the same SelectivePresentation> (in train_dataloader(), reuse one)"
            )
        counted, want = trainer.num_training_batches, len(loaders[0])
        if s.epoch != trainer.current_epoch or (trainer.limit_train_batches == 1.0 and counted != want):
            raise RuntimeError(
                f"epoch {trainer.current_epoch}: Lightning counted {counted} batches with the sampler at epoch "
                f"{s.epoch}, but the stage's training set of {s.subset().numel()} patterns makes {want}"
            )
        s.expect_new_pass()  # Lightning re-creates its iterator after a worker prefetch: not a repeated epoch

    def on_train_epoch_end(self, trainer: pl.Trainer, pl_module: pl.LightningModule) -> None:
        following = trainer.current_epoch + 1  # the epoch Lightning counts next (current_epoch moves after this)
        if following < self.sampler.num_epochs:
            self.sampler.set_epoch(following)

    def on_fit_end(self, trainer: pl.Trainer, pl_module: pl.LightningModule) -> None:
        """A last epoch the Trainer left unfinished is said now, with Lightning's reason."""
        if trainer.max_steps != -1 and trainer.global_step >= trainer.max_steps:
            cause = f"Trainer(max_steps={trainer.max_steps}) stopped it"
        elif trainer.limit_train_batches != 1.0:
            cause = f"Trainer(limit_train_batches={trainer.limit_train_batches}) ends every epoch early"
        else:
            cause = "the Trainer stopped it (should_stop: early stopping, a callback, or an interrupt)"
        self.sampler.finish(cause)
