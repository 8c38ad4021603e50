"""A live fine-tuning session from start to end: `start(spec)`, `resume(out, ...)`, `replay(source, out)`.

The command (`protamer finetune`) parses its arguments into a `SessionSpec` and calls one of these. Each claims
its output directory first (outdir.py: new or empty, or the session itself for a resume; locked), checks the
voice front end's weights and devices, then loads the checkpoint (live/build.py), builds the learner, the
feedback sources (live/sources.py) and the sinks (live/sinks.py), and runs the loop (live/loop.py). Every save
(autosave and the last) writes the learner's trees with checksums (experiments/checkpoints.py), the configs
atomically, and a `saved` line in the record; a write that fails ends the session with one line naming the
path and the last good save.

Exit codes: 0 normal end, 130 Ctrl-C / 143 SIGTERM (after saving), 2 a bad argument, checkpoint, output
directory or record, 1 a write that failed, the voice front end's codes (3 audio input, 4 audio device, 5 missing
weights, 6 calibration) when the audio source, weights or calibration are unusable (checked before loading),
or, at the end of a session that went on without it, when the voice listener died.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

from mjx_protamer.compile_cache import enable as enable_compile_cache
from mjx_protamer.live.spec import SessionSpec

KIND = "finetune-session"  # what outdir.claim records


def _fail(msg: str, code: int = 2) -> int:
    print(f"protamer finetune: {msg}", file=sys.stderr, flush=True)
    return code


def _voice_check(spec: SessionSpec):
    """(VoiceError exit code, message) or None, before anything heavy: the audio source, calibration, weights."""
    if not spec.voice:
        return None
    from audio_frontend.errors import AudioDeviceError, VoiceError
    from audio_frontend.preflight import check_voice_feedback

    try:
        if spec.speaker:
            from mjx_protamer.live.speaker import speaker_voice_config
            cfg = speaker_voice_config(spec)
        else:
            from mjx_protamer.live.sources import voice_setup
            cfg, _ = voice_setup(spec.voice_config, spec.voice_set, spec.listen_source)
        print("[finetune] voice: " + "; ".join(check_voice_feedback(cfg, spec.feedback, spec.keywords_only)),
              flush=True)
    except VoiceError as e:
        hint = " (here: --listen-source wav:PATH or speaker)" if isinstance(e, AudioDeviceError) else ""
        return e.exit_code, f"{e}{hint}"
    return None


def _sources(spec: SessionSpec, learner, loaded, clock, segment: int) -> list:
    from mjx_protamer.live import sources as S

    if spec.feedback == "keyboard":
        return [S.KeyboardSource(learner.queue)]
    if spec.feedback == "web":
        return [S.PageSource()]
    if spec.feedback.startswith("simulated:"):
        return [S.SimulatedTeacher(learner.queue, spec.config.feedback.teacher, spec.config.feedback.dt,
                                   spec.config.feedback.seed + 7919 * segment, loaded.env, clock)]
    if spec.speaker:
        from mjx_protamer.live.speaker import SimulatedSpeaker
        return [SimulatedSpeaker(spec, learner.queue, loaded.env, segment)]
    if spec.voice:
        cfg, audio = S.voice_setup(spec.voice_config, spec.voice_set, spec.listen_source)
        return [S.VoiceSource(learner.queue, cfg, spec.feedback, audio, spec.listen_source,
                              spec.save_segments or str(spec.out / "segments"), spec.keywords_only)]
    return []


class Saver:
    """Every save: the learner's trees (checksummed), the configs (atomic), a `saved` line in the record."""

    def __init__(self, spec: SessionSpec, learner, loaded, recorder, first_save: int):
        self.spec, self.learner, self.loaded, self.recorder = spec, learner, loaded, recorder
        self.next = first_save
        self.last_good: str | None = None

    def __call__(self) -> None:
        import jax
        import yaml

        from mjx_protamer.atomic import write_atomic
        from mjx_protamer.config import to_dict
        from mjx_protamer.experiments import checkpoints
        from mjx_protamer.errors import WriteFailed

        out = self.spec.out
        try:
            for name, tree in self.learner.trees().items():
                mngr = checkpoints.manager(out / name)
                try:
                    checkpoints.save(mngr, self.next, jax.device_get(tree))
                finally:
                    mngr.close()
            if self.spec.learner_kind.pretrain_run:  # loadable by `protamer eval --checkpoint OUT` and finetune again
                write_atomic(out / "config.yaml", yaml.safe_dump(to_dict(self.learner.config), sort_keys=False))
            write_atomic(out / "feedback_config.yaml", yaml.safe_dump(to_dict(self.spec.config), sort_keys=False))
            if self.recorder is not None:
                self.recorder.saved(self.next, self.learner.first_step)
        except Exception as e:  # OSError (disk full, permissions), or orbax's own wrapping of one
            where = getattr(e, "filename", None) or out
            raise WriteFailed(f"saving into {where} failed ({type(e).__name__}: {e}); the last good save is "
                              f"{self.last_good or 'none: the session had not saved yet'}") from None
        self.last_good = f"save {self.next} at step {self.learner.first_step} in {out}"
        self.next += 1


def _run(spec: SessionSpec, loaded, learner, recorder, clock, saver: Saver, segment: int) -> int:
    """View, sources, loop, the final drain and save, cleanup; the exit code."""
    from mjx_protamer.errors import WriteFailed
    from mjx_protamer.live.loop import LoopResult, Stopper, run_loop
    from mjx_protamer.live.pace import UpdatePacer
    from mjx_protamer.live.sinks import (RecordSink, SnapshotSink, TerminalSink, ViewSink, calibration_prompt,
                                         start_view)

    view, why = start_view(spec.view, loaded.pre, learner.queue, spec.port)
    if view is None and why is not None:
        if spec.feedback == "web":  # the page is this session's only feedback: nothing to run without it
            return _fail(f"--feedback web: the live page cannot start ({why}); free the port or give another "
                         "--port", 2)
        print(f"[view] not available ({why}); the session goes on without it", flush=True)
    sources = _sources(spec, learner, loaded, clock, segment)
    record = RecordSink(recorder)
    view_sink = ViewSink(view, spec) if view is not None else None
    sinks = [TerminalSink(), record] + ([view_sink] if view_sink is not None else [])
    if spec.snapshot_every_s > 0:
        sinks.append(SnapshotSink(spec.out, round(spec.snapshot_every_s / learner.dt)))
    sc = spec.config.session
    pacer = UpdatePacer(learner.chunk_steps, learner.dt, sc.chunk_updates_per_step, sc.max_updates_per_step,
                        sc.spare_fraction, sc.unpaced_updates_per_step, paced=spec.pace and spec.live,
                        updates_per_event=sc.updates_per_event if spec.learner_kind.replay_updates else 0.0)
    for line in learner.intro(spec):
        print(f"[finetune] {line}", flush=True)

    if getattr(learner, "attention", None) is not None:
        print("[finetune] credit.silence_needs_attention: a silent step teaches 'nothing to say' only while the "
              "live page is visible", flush=True)

    def on_ready():
        for s in sources:
            s.start()
        lines = [s.ready_line() for s in sources if s.ready_line()]
        if lines:
            print(f"[finetune] ready: {lines[0]}", flush=True)
        if spec.calibrate is not None:
            print(f"[calibrate] {calibration_prompt(spec.calibrate)}; at the end your reaction delay is fitted",
                  flush=True)

    code = 0
    with Stopper() as stopper:
        try:
            print("[finetune] compiling (first chunk and feedback update)...", flush=True)
            learner.warm_up()
            result = run_loop(spec, learner, sources, sinks, pacer, clock, stopper, saver, on_ready)
        except KeyboardInterrupt:  # a second Ctrl-C while compiling
            result = LoopResult(interrupted=True)
        finally:
            for s in sources:
                s.stop()
        final = learner.take_events(max(0, learner.first_step - 1))  # whatever arrived last
        TerminalSink.outcomes(final)
        for src in sources:
            src.drained(final)
            src.finish()
        write_error = result.write_error
        try:
            recorder.final([o.event for o in final])
        except OSError as e:
            write_error = write_error or f"the record could not be written ({e})"
        if view_sink is not None:
            view_sink.close()
        if write_error is None:
            try:
                saver()
            except WriteFailed as e:
                write_error = str(e)
        record.close()
        learner.close()
    if write_error is not None:
        return _fail(write_error, 1)
    s = learner.status()
    pace = {**result.pace(learner.chunk_steps * learner.dt), "segment": segment, "paced": pacer.paced,
            "updates_per_step": pacer.updates_per_step() if spec.learner_kind.replay_updates else None,
            **(pacer.costs() if pacer.paced and spec.learner_kind.replay_updates else {})}
    _record_pace(spec.out, pace)
    ups = f", {pace['updates_per_step']:.2f} updates per shown step" if pace["updates_per_step"] is not None else ""
    rt = f", {pace['realtime']:.2f}x real time" if "realtime" in pace else ""
    print(f"[finetune] saved in {spec.out}: {s['events']} events{' since the resume' if segment else ''}, queue "
          f"{learner.queue.stats()}{ups}{rt}", flush=True)
    if spec.calibrate is not None:  # the session is saved whatever the fit says
        from mjx_protamer.live.reaction_delay import measure

        out = spec.out
        for old in (out / "reaction_delay.json", out / "reaction_delay.png"):  # an earlier stretch's fit
            old.unlink(missing_ok=True)
        print(f"[calibrate] the reaction delay of this session ({spec.calibrate} onsets):", flush=True)
        code = measure(out, spec.calibrate, json_path=out / "reaction_delay.json", plot_path=out / "reaction_delay.png",
                       who="[calibrate] no fit", rerun=f"protamer reaction-delay {out}")
    died = max((src.exit_code for src in sources), default=0)
    if stopper.signum is not None:
        return 128 + stopper.signum  # 130 for Ctrl-C, 143 for SIGTERM
    if died and not result.interrupted:  # the session went on without voice feedback: not a success
        print(f"[finetune] exit code {died}: the voice listener died during the session (see above); everything up "
              "to then is saved", flush=True)
        return died
    if result.interrupted:
        return 130
    if code:
        print(f"[finetune] exit code {code}: the session is saved, its reaction delay could not be fitted (above)",
              flush=True)
    return code


def _record_pace(out: Path, pace: dict) -> None:
    """session.json keeps each segment's measured pace (`measured_pace`): real-time factor, updates per shown step."""
    from mjx_protamer.live.record import MANIFEST, read_manifest, write_json_atomic

    manifest = read_manifest(out)
    manifest.setdefault("measured_pace", []).append(pace)
    write_json_atomic(out / MANIFEST, manifest)


def _clock(spec: SessionSpec):
    """Wall time for a live session (events carry it); a virtual clock advancing with the shown steps for a
    simulated teacher or no feedback, so an unpaced session's teacher reacts in shown time."""
    from mjx_protamer.human.clock import VirtualClock

    return time.time if spec.live else VirtualClock(start=time.time())


def start(spec: SessionSpec) -> int:
    """A new session from `spec.checkpoint` into `spec.out`."""
    from mjx_protamer.errors import CheckpointError
    from mjx_protamer.experiments.run_loader import read_run_config, resolve_checkpoint
    from mjx_protamer.live.build import build_learner, load_checkpoint
    from mjx_protamer.live.record import MANIFEST, FORMAT, SessionRecorder, write_json_atomic
    from mjx_protamer.outdir import claim

    if spec.feedback == "keyboard" and not sys.stdin.isatty():
        return _fail("--feedback keyboard reads keys from the terminal, but stdin is not a terminal (tty). Run it in "
                     "an interactive terminal (or tmux/screen), or use --feedback simulated:keyboard for a run "
                     "without a human.")
    if spec.checkpoint is None:
        return _fail("--checkpoint is required (a pretrain run directory), unless --resume or --replay")
    voice = _voice_check(spec)  # the audio source, calibration and weights, before the checkpoint is read
    if voice is not None:
        return _fail(voice[1], voice[0])
    if not Path(spec.checkpoint).exists():
        return _fail(f"--checkpoint {spec.checkpoint}: no such file or directory. Give a pretrain run directory "
                     "(made by `protamer pretrain --out DIR`) or a finetune output directory.")
    try:
        run_dir = resolve_checkpoint(spec.checkpoint)[0]
        env_name = read_run_config(run_dir).env_name
    except CheckpointError as e:
        return _fail(f"--checkpoint: {e} (expected DIR/config.yaml and DIR/checkpoints/<step>/)")
    except Exception as e:  # an unreadable config.yaml
        return _fail(f"--checkpoint {spec.checkpoint}: its config.yaml cannot be read ({type(e).__name__}: {e})")
    if spec.calibrate is not None and env_name != "self_touch":
        return _fail(f"--calibrate needs a self-touch checkpoint (touches to react to); {spec.checkpoint} is a "
                     f"{env_name} run")
    lease = claim(spec.out, KIND)
    try:
        enable_compile_cache()  # the next session on this checkpoint starts in seconds
        print(f"[finetune] loading {spec.checkpoint} (the first chunk compiles: this can take a minute or two)",
              flush=True)
        try:
            loaded = load_checkpoint(Path(spec.checkpoint))
        except CheckpointError as e:
            return _fail(f"--checkpoint: {e}")
        clock = _clock(spec)
        learner = build_learner(spec, loaded, clock, log_path=spec.out / "feedback.jsonl")
        manifest = {**spec.manifest(), **loaded.identity, "record_format": FORMAT, "started": time.time(),
                    "seeds": {"train": loaded.pre.train.seed, "feedback": spec.config.feedback.seed}}
        write_json_atomic(spec.out / MANIFEST, manifest)
        recorder = SessionRecorder(spec.out)
        if learner.log is not None:
            learner.log.note(event="start", feedback=spec.feedback, learner=spec.learner,
                             checkpoint=str(spec.checkpoint), checkpoint_step=loaded.step,
                             chunk_steps=spec.chunk_steps, dt=spec.config.feedback.dt)
        print(f"[finetune] {spec.learner} from {spec.checkpoint} (step {loaded.step}); chunks of {spec.chunk_steps} "
              f"steps ({spec.chunk_ms:.0f} ms); feedback {spec.feedback}; output {spec.out}", flush=True)
        return _run(spec, loaded, learner, recorder, clock, Saver(spec, learner, loaded, recorder, 0), 0)
    finally:
        lease.release()


def _checkpoint_of(manifest: dict, session: Path):
    """The checkpoint a recorded session started from, checked unchanged (its SHA-256)."""
    from mjx_protamer.errors import SessionRecordError
    from mjx_protamer.live.record import tree_sha256

    try:
        step_dir = Path(manifest["checkpoint_step_dir"])
        want = manifest["checkpoint_sha256"]
    except (KeyError, TypeError):
        raise SessionRecordError(f"{session / 'session.json'} does not name the checkpoint the session started "
                                 "from; the record is damaged") from None
    if not step_dir.is_dir() or tree_sha256(step_dir) != want:
        raise SessionRecordError(f"the session started from {step_dir}, which is missing or has changed (SHA-256 "
                                 "differs); a replay or resume needs the very same checkpoint")
    return step_dir


def resume(out: Path, **flags) -> int:
    """Continue the session in `out` from its newest intact save (a new segment of the record)."""
    from mjx_protamer.errors import CheckpointError, SessionRecordError
    from mjx_protamer.experiments import checkpoints
    from mjx_protamer.live.build import build_learner, load_checkpoint
    from mjx_protamer.live.record import (MANIFEST, SessionRecorder, line_count, read_manifest, read_session,
                                          repair_torn_tail, write_json_atomic)
    from mjx_protamer.outdir import claim

    lease = claim(out, KIND, resume=True, own=(MANIFEST,))
    try:
        manifest = read_manifest(out)
        spec = SessionSpec.from_manifest(manifest, out, **flags)
        spec.check()
        if repair_torn_tail(out):
            print("[finetune] the record's last line was torn (the session was killed while writing it): cut",
                  flush=True)
        _, records = read_session(out)
        saves = {int(r["saved"]): r for r in records if "saved" in r}
        segment = 1 + max((int(r.get("segment", 0)) for r in records), default=0)
        step_dir = _checkpoint_of(manifest, out)
        voice = _voice_check(spec)
        if voice is not None:
            return _fail(voice[1], voice[0])
        enable_compile_cache()
        try:
            loaded = load_checkpoint(step_dir, backend=manifest.get("env_backend"))
        except CheckpointError as e:
            return _fail(f"--resume: the session's checkpoint {step_dir}: {e}")
        clock = _clock(spec)
        learner = build_learner(spec, loaded, clock, log_path=out / "feedback.jsonl", segment=segment)
        names = list(learner.trees())
        mngrs = [checkpoints.manager(out / n) for n in names]
        try:
            like = [jax_shape(t) for t in learner.trees().values()]
            save, trees = checkpoints.restore_newest_intact(list(zip(mngrs, like)),
                                                             lambda line: print(f"[finetune] {line}", flush=True))
        finally:
            for m in mngrs:
                m.close()
        if save is None:
            return _fail(f"--resume: {out} has no save yet (it stopped before the first autosave); start a new "
                         "session")
        recorder = SessionRecorder(out, segment=segment, next_line=line_count(out))
        if save not in saves:
            if saves and save != max(saves) + 1 or not saves and save != 0:
                raise SessionRecordError(f"{out}: save {save} is not in the record; the record is damaged")
            # killed between the save and its line: the record ends where that save was taken
            recorder.saved(save, _steps_recorded(records, spec.chunk_steps))
            _, records = read_session(out)
            saves = {int(r["saved"]): r for r in records if "saved" in r}
        learner.set_trees(dict(zip(names, trees)))
        learner.begin_at(int(saves[save]["step"]))
        recorder.resume(save, time.time())
        manifest.setdefault("resumed", []).append({"at_step": learner.first_step, "save": save, "segment": segment,
                                                   "time": time.time()})
        write_json_atomic(out / MANIFEST, manifest)
        if learner.log is not None:
            learner.log.note(event="resume", feedback=spec.feedback, learner=spec.learner, save=save,
                             at_step=learner.first_step, segment=segment)
        print(f"[finetune] {spec.learner} session {out} resumed at step {learner.first_step} (save {save}); "
              f"feedback {spec.feedback}", flush=True)
        return _run(spec, loaded, learner, recorder, clock, Saver(spec, learner, loaded, recorder, save + 1), segment)
    finally:
        lease.release()


def jax_shape(tree):
    import jax

    return jax.eval_shape(lambda: tree)


def _steps_recorded(records: list[dict], chunk_steps: int) -> int:
    chunks = [r for r in records if "first_step" in r]
    return chunks[-1]["first_step"] + chunk_steps if chunks else 0


def replay(source: Path, out: Path) -> int:
    """Rerun the session recorded in `source` headless into `out`: the same checkpoint, configs and chunks, each
    drain given the recorded events, each chunk its recorded extra updates, each resume a new segment."""
    from mjx_protamer.errors import CheckpointError
    from mjx_protamer.live.build import adopt, build_learner, load_checkpoint
    from mjx_protamer.live.record import ScriptedQueue, read_session
    from mjx_protamer.outdir import claim

    if Path(out).absolute() == Path(source).absolute():
        return _fail("--replay: --out must be a new directory, not the session's own")
    manifest, records = read_session(source)
    spec = SessionSpec.from_manifest(manifest, Path(out), view="none", pace=False, autosave_s=0.0)
    step_dir = _checkpoint_of(manifest, Path(source))
    lease = claim(out, KIND)
    try:
        enable_compile_cache()
        try:
            loaded = load_checkpoint(step_dir, backend=manifest.get("env_backend"))
        except CheckpointError as e:
            return _fail(f"--replay: the session's checkpoint {step_dir}: {e}")
        segments: list[list[dict]] = [[]]
        for r in records:
            if "resume" in r:
                segments.append([])
            elif "first_step" in r or r.get("final"):
                segments[-1].append(r)
        chunks = sum(1 for r in records if "first_step" in r)
        print(f"[replay] {spec.learner} session of {chunks} chunks in {len(segments)} segment(s), "
              f"{sum(len(r['events']) for r in records)} events, from {step_dir}", flush=True)
        learner = None
        for k, seg in enumerate(segments):
            queue = ScriptedQueue([r["events"] for r in seg])
            previous = learner
            learner = build_learner(spec, loaded, _clock(spec), queue=queue,
                                    log_path=Path(out) / "feedback.jsonl", segment=k)
            if previous is not None:
                adopt(learner, previous)
                previous.close()
            for r in seg:
                if r.get("final"):
                    learner.take_events(max(0, learner.first_step - 1))
                    continue
                chunk = learner.step_chunk(float(r["t0"]))
                learner.take_events(chunk.first_step + learner.chunk_steps - 1)
                learner.extra_updates(int(r.get("extra", 0)))
        Saver(spec, learner, loaded, None, 0)()
        learner.close()
        print(f"[replay] done: step {learner.first_step}, {learner.events} events; saved in {out}", flush=True)
        return 0
    finally:
        lease.release()
