# SPDX-License-Identifier: GPL-3.0-or-later
"""Generate Locomotion for many rigs at once: every rig read and checked, then as few core
simulations as the rigs allow, each stepping all its rigs together frame by frame.

- :func:`read_all` reads every rig (:func:`.generate.read`; :func:`read_all_steps` as
  progress steps); a refusal names the rig and nothing is changed on any rig. The terrain
  of a batch leaves out every rig of it (a neighbour's skin is not ground: the neighbour is
  a character of the same simulation).
- :func:`vary` gives copies of one creature their own phase and stride (Seed Offset, and an
  automatic variation for linked duplicates and rigs with identical settings).
- :func:`batches` groups the rigs that can share one simulation: the same frames, the same
  terrain objects and the same mean foot height (the core's terrain is raised by it; see
  :func:`.simulation.batch_key`). Rigs of
  different frame ranges are each walked over their own range, in simulations of their own:
  an animator who gave a rig its own range expects that range, and those rigs do not see
  the others.
- :func:`read_terrain` reads each batch's terrain once and checks there is ground under
  every rig; :func:`simulate` runs each batch's simulation.
"""

from __future__ import annotations

import time
import zlib
from collections.abc import Generator, Iterator, Sequence
from dataclasses import dataclass, replace

import bpy
import numpy as np

from ...core.steps import run_steps
from .. import rig, scene_terrain
from . import simulation
from .job import Job, settings_values

__all__ = ["CYCLE_VARIATION", "Batch", "batches", "read_all", "read_all_steps", "read_terrain", "simulate",
           "variation", "vary"]

#: Largest change of a varied rig's cycle times (a share: ±4 %).
CYCLE_VARIATION = 0.04


@dataclass
class Batch:
    """Rigs simulated together: their jobs, in the order given, and their terrain's objects."""

    jobs: list[Job]
    terrain_objects: tuple[str, ...]

    @property
    def names(self) -> str:
        """The rigs, for progress messages: the first and how many more."""
        more = len(self.jobs) - 1
        return self.jobs[0].obj_name + (f" and {more} more" if more else "")


def read_all(context: bpy.types.Context, objects: Sequence[bpy.types.Object | None]) -> list[Job]:
    """Read and check every rig (not the terrain: :func:`read_terrain`), then :func:`vary`
    them. Raises ``GenerateError`` naming the rig refused; changes nothing."""
    return run_steps(read_all_steps(context, objects))


def read_all_steps(context: bpy.types.Context, objects: Sequence[bpy.types.Object | None],
                   ) -> Generator[float, None, list[Job]]:
    """:func:`read_all` as progress steps: yields the fraction of the rigs read (the
    operator shows it and stops on Esc while a herd is read); returns the jobs."""
    from . import generate

    jobs = []
    with rig.reading_once():  # nothing changes while the rigs are read: copies are detected once
        for k, obj in enumerate(objects):
            try:
                job = generate.read(context, obj)
            except generate.GenerateError as err:
                name = "" if obj is None else obj.name
                if name and f"'{name}'" not in str(err):
                    raise generate.GenerateError(f"'{name}': {err}") from err
                raise
            jobs.append(job)
            yield (k + 1) / max(len(objects), 1)
    names = {job.obj_name for job in jobs}
    if len(names) < len(jobs):
        raise generate.GenerateError("A rig is listed twice: each rig is generated once")
    if len(jobs) > 1:
        rigs = [bpy.data.objects[job.obj_name] for job in jobs]
        found: dict[str, list[bpy.types.Object]] = {}  # by terrain collection: the same for all its rigs
        for job, obj in zip(jobs, rigs, strict=True):
            collection = obj.procloco.terrain_collection
            where = "" if collection is None else collection.name
            if where not in found:
                found[where] = scene_terrain.terrain_objects(context, rigs, collection)
            objs = found[where]
            if not objs:
                raise generate.GenerateError(f"No ground mesh found for '{obj.name}': add a mesh under the "
                                             "creature (or choose the terrain collection); the other rigs "
                                             "generated with it are not ground")
            job.terrain_objects = tuple(o.name for o in objs)
    vary(jobs)
    return jobs


def variation(key: int) -> tuple[float, float]:
    """``(phase, cycle scale)`` of a variation ``key``: a start phase in cycles [0, 1) and a
    factor on the cycle times within ±:data:`CYCLE_VARIATION`, the same for the same key."""
    rng = np.random.default_rng([key & 0xFFFFFFFF, (key >> 32) & 0xFFFFFFFF, 17])
    phase, u = rng.uniform(0.0, 1.0, 2)
    return float(phase), 1.0 + CYCLE_VARIATION * (2.0 * float(u) - 1.0)


def _signature(job: Job) -> tuple[object, ...]:
    """What makes two rigs walk alike (wherever they stand): their settings, gait and legs."""
    settings = bpy.data.objects[job.obj_name].procloco
    values = settings_values(settings)
    values.pop("seed_offset", None)
    return (tuple(sorted(values.items())), round(float(settings.heading), 9), round(job.gait.cycle_time, 9),
            tuple(np.round(job.gait.swing_start, 9)),
            tuple(np.round(job.gait.swing_duration, 9)), job.auto_gait is None, job.path is None,
            tuple(np.round(job.info.leg_length, 6)), len(job.gait_changes))


def vary(jobs: Sequence[Job]) -> None:
    """Give each rig its variation (:func:`variation`, into its phase and gaits): a rig's
    Seed Offset when it is not 0; else, for a rig that shares its armature data with another
    rig of ``jobs`` (a linked duplicate) or walks with exactly the settings of another (a
    copy), a key from its object's name, so copies do not walk in step. Any other rig, and a
    rig alone with offset 0, is left exactly as it is."""
    data = [bpy.data.objects[job.obj_name].data for job in jobs]
    signatures = [_signature(job) for job in jobs] if len(jobs) > 1 else []
    for k, job in enumerate(jobs):
        if job.seed_offset != 0:
            key = int(job.seed_offset)
        elif len(jobs) > 1 and (sum(d == data[k] for d in data) > 1 or signatures.count(signatures[k]) > 1):
            key = zlib.crc32(job.obj_name.encode("utf-8"))
        else:
            continue
        _apply_variation(job, *variation(key))


def _apply_variation(job: Job, phase: float, scale: float) -> None:
    """The start phase and the cycle times: the gaits' (circles and Gait Changes), or with
    Gait: Auto the creature's size (its cycle follows the square root of it, Froude)."""
    job.phase, job.cycle_scale = phase, scale
    job.gait = replace(job.gait, cycle_time=job.gait.cycle_time * scale)
    job.gait_changes = tuple(replace(c, gait=replace(c.gait, cycle_time=c.gait.cycle_time * scale))
                             for c in job.gait_changes)
    if job.auto_gait is not None:
        job.auto_gait = replace(job.auto_gait, size=job.auto_gait.size * scale * scale)


def batches(jobs: Sequence[Job]) -> list[Batch]:
    """The rigs of ``jobs`` grouped into simulations (see the module doc), in the order of
    their first rig."""
    out: dict[tuple[object, ...], Batch] = {}
    for job in jobs:
        key = (int(job.frames[0]), int(job.frames[-1]), round(job.dt, 12), job.terrain_objects,
               simulation.batch_key(job))
        if key not in out:
            out[key] = Batch([], job.terrain_objects)
        out[key].jobs.append(job)
    return list(out.values())


def read_terrain(context: bpy.types.Context, groups: Sequence[Batch]) -> Iterator[float]:
    """Read each batch's terrain once (animated objects played over its frames) and check
    there is ground under each of its rigs, yielding the fraction done. Raises
    ``GenerateError``; changes nothing (the scene's frame is put back)."""
    from . import generate

    total = sum(len(g.jobs) for g in groups)
    done = 0
    for group in groups:
        t0 = time.perf_counter()
        lead = replace(group.jobs[0], warnings=[], timings={})
        steps = generate.read_terrain(context, lead)
        n = len(group.jobs)
        yield from ((done + n * f) / total for f in steps)
        terrain = lead.terrain
        assert terrain is not None
        for job in group.jobs:
            obj = bpy.data.objects[job.obj_name]
            try:
                scene_terrain.check_ground_under(terrain, job.info.contact, obj.name,
                                                 reach=float(np.mean(job.info.leg_length)))
            except scene_terrain.TerrainError as err:
                raise generate.GenerateError(str(err) + scene_terrain.hidden_note(context, [obj])) from err
            job.terrain = terrain
            job.warnings.extend(terrain.warnings)
            job.timings["read_s"] = job.timings.get("read_s", 0.0) + (time.perf_counter() - t0) / n
        done += len(group.jobs)


def simulate(groups: Sequence[Batch]) -> Iterator[tuple[str, float]]:
    """Run each batch's simulation; yields ``(the batch's rigs, fraction of all done)``.
    Each job's tracks land in ``job.result``."""
    total = sum(len(g.jobs) * g.jobs[0].frames.shape[0] for g in groups)
    done = 0
    for group in groups:
        t0 = time.perf_counter()
        weight = len(group.jobs) * group.jobs[0].frames.shape[0]
        for fraction in simulation.run_all(group.jobs):
            yield group.names, (done + weight * fraction) / total
        done += weight
        for job in group.jobs:
            job.timings["simulate_s"] = (time.perf_counter() - t0) / len(group.jobs)
