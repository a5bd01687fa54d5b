"""The command's checkpoints: the engine's (`jaxgrasp.engine._checkpoint`), with the
words the command says of them (`_notes`): what an interrupt prints, what a failed
write's error adds, and which damaged chunk files ``--resume`` skipped."""

from __future__ import annotations

from jaxgrasp.cli._notes import set_keeping, set_last_write, set_note
from jaxgrasp import engine
from jaxgrasp.model import counted

__all__ = ["SweepKeeper", "BatchCheckpoint"]


class SweepKeeper(engine.SweepKeeper):
    """``jaxgrasp sweep``'s checkpoint (`jaxgrasp.engine._checkpoint.SweepKeeper`):
    a skipped write is left to an interrupt (`set_last_write`), and each write
    leaves the note an interrupt prints (``kept K of N points in PATH``) and what a failed
    write's error adds."""

    def deferred(self, write) -> None:
        set_last_write("sweep", write)

    def kept(self, partial) -> None:
        set_note("sweep", f"kept {partial.done_count} of {self.total} points in {self.path}")
        set_keeping("sweep", f"{partial.done_count} of {self.total} finished points kept in {self.path}")


class BatchCheckpoint(engine.BatchCheckpoint):
    """``jaxgrasp batch``'s checkpoint (`jaxgrasp.engine._checkpoint.BatchCheckpoint`)
    with the command's words: once opened, a failed write's error says the folder is kept;
    each chunk kept leaves the note an interrupt prints; `skipped_note` names the
    damaged chunk files ``--resume`` skipped."""

    def open(self, resume: bool):
        opened = super().open(resume)
        set_keeping("batch", f"finished chunks kept in {self.folder}, rerun with --resume")
        return opened

    def kept(self, rows: int, total: int) -> None:
        set_note(
            "batch",
            f"kept {rows} of {counted(total, 'grasp')} in {self.folder}; "
            "the same command with --resume finishes the rest",
        )

    def skipped_note(self) -> str | None:
        """One line on the chunk files the last `load` skipped (``None``: none): damaged
        ones and other runs' (each file's reason says which)."""
        if not self.skipped:
            return None
        n = len(self.skipped)
        return (
            f"jaxgrasp: --resume: skipped {n} damaged chunk file{'s' if n > 1 else ''} in {self.folder} "
            f"(first: {self.skipped[0]}); {'their' if n > 1 else 'its'} grasps are evaluated again"
        )
