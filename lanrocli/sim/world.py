"""The physics client, its clock and the table.

Each ``World`` owns a private PyBullet client, so several worlds (for example one per
vectorised environment) can live in one process without seeing each other's bodies.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from types import TracebackType

import numpy as np
import numpy.typing as npt
import pybullet
import pybullet_data
from pybullet_utils.bullet_client import BulletClient

from lanrocli.sim.camera import Camera, CameraPose
from lanrocli.sim.layout import (
    CONTROL_DT,
    FLOOR_HEIGHT,
    GRAVITY,
    SOLVER_ITERATIONS,
    SUBSTEPS,
    TABLE_CENTRE,
    TABLE_HALF_EXTENTS,
    TABLE_LATERAL_FRICTION,
)

TABLE_RGBA = (0.82, 0.78, 0.70, 1.0)


@contextmanager
def _native_stdout_silenced() -> Iterator[None]:
    """Discard what PyBullet's C code prints on stdout while connecting ("argv[0]=").

    Commands such as ``lanro eval --json`` promise clean machine-readable stdout.
    """
    sys.stdout.flush()
    saved = os.dup(1)
    try:
        with open(os.devnull, "w") as devnull:
            os.dup2(devnull.fileno(), 1)
        yield
    finally:
        os.dup2(saved, 1)
        os.close(saved)


class World:
    """A PyBullet world with a table whose top is the plane z = 0, on a floor at its foot.

    One control step is a single ``stepSimulation`` call that PyBullet splits into
    ``SUBSTEPS`` physics steps of 1 / ``PHYSICS_HZ`` s. That is faster than 20 calls from
    Python (docs/performance.md), and gives bit-identical trajectories once motor force limits are
    multiplied by ``motor_force_scale``: PyBullet sizes the motors' impulse budget with the
    whole control step, not the physics step.

    ``revision`` increases whenever the state may have changed (a step or a reset), so
    that robot and object state queries can be cached between changes.

    ``images=False`` declares that nothing will ever draw this world (no camera image, no GUI), so the arm
    is loaded without its visual meshes, which take most of the time an environment takes to build;
    the physics are the same either way.
    """

    def __init__(self, gui: bool = False, camera: CameraPose | None = None, images: bool = True) -> None:
        if gui and not images:
            raise ValueError("a world shown in the GUI is drawn: it needs images=True")
        camera = camera if camera is not None else CameraPose()
        self.images = images
        with _native_stdout_silenced():
            self._client = BulletClient(connection_mode=pybullet.GUI if gui else pybullet.DIRECT)
        self._closed = False
        client = self._client
        client.setAdditionalSearchPath(pybullet_data.getDataPath())
        client.setPhysicsEngineParameter(
            fixedTimeStep=CONTROL_DT,
            numSubSteps=SUBSTEPS,
            numSolverIterations=SOLVER_ITERATIONS,
            deterministicOverlappingPairs=1,
        )
        client.setGravity(*GRAVITY)
        if gui:
            client.configureDebugVisualizer(pybullet.COV_ENABLE_GUI, 0)
            client.resetDebugVisualizerCamera(
                cameraDistance=camera.distance,
                cameraYaw=camera.yaw,
                cameraPitch=camera.pitch,
                cameraTargetPosition=camera.target,
            )
        self.table_id = self._create_table()
        self._camera = Camera(client, camera)
        self._step_simulation = client.stepSimulation
        self._steps = 0
        self._revision = 0

    def _create_table(self) -> int:
        client = self._client
        collision = client.createCollisionShape(pybullet.GEOM_BOX, halfExtents=TABLE_HALF_EXTENTS)
        visual = client.createVisualShape(pybullet.GEOM_BOX, halfExtents=TABLE_HALF_EXTENTS, rgbaColor=TABLE_RGBA)
        table = client.createMultiBody(
            baseMass=0.0,
            baseCollisionShapeIndex=collision,
            baseVisualShapeIndex=visual,
            basePosition=TABLE_CENTRE,
        )
        client.changeDynamics(table, -1, lateralFriction=TABLE_LATERAL_FRICTION)
        # The floor: an object pushed off the table lands and rests instead of falling without end, so what
        # the observation reports of it stays within the room.
        floor = client.createCollisionShape(pybullet.GEOM_PLANE)
        client.createMultiBody(baseMass=0.0, baseCollisionShapeIndex=floor, basePosition=(0.0, 0.0, FLOOR_HEIGHT))
        return int(table)

    @property
    def client(self) -> BulletClient:
        """The private PyBullet client; the robot and objects create their bodies in it."""
        return self._client

    @property
    def motor_force_scale(self) -> float:
        """Factor for force and torque limits passed to PyBullet's joint motors.

        Multiplying the physical limit (N or N m) by it makes the motors exert that limit
        during every physics substep.
        """
        return 1.0 / SUBSTEPS

    @property
    def steps(self) -> int:
        """Control steps taken since the world was created."""
        return self._steps

    @property
    def time(self) -> float:
        """Simulated seconds since the world was created."""
        return self._steps * CONTROL_DT

    @property
    def revision(self) -> int:
        """Counter that changes whenever cached states must be re-read."""
        return self._revision

    def invalidate(self) -> None:
        """Mark cached states stale; called by whoever teleports bodies."""
        self._revision += 1

    def step_physics(self) -> None:
        """Only the physics of one control step; for timing bare physics in benchmarks.

        It neither advances ``time`` nor invalidates cached states, so environments must
        call ``step`` instead.
        """
        self._step_simulation()

    def step(self) -> None:
        """Advance the simulation by one control step (``CONTROL_DT`` seconds)."""
        self.step_physics()
        self._steps += 1
        self._revision += 1

    def render(self, width: int = 320, height: int = 240) -> npt.NDArray[np.uint8]:
        """RGB uint8 image of shape (height, width, 3) of the table and the arm."""
        if not self.images:
            raise RuntimeError("this world was built with images=False: build it with images=True to draw it")
        return self._camera.render(width, height)

    def close(self) -> None:
        """Disconnect the client; safe to call more than once."""
        if not self._closed:
            self._closed = True
            self._client.disconnect()

    def __enter__(self) -> World:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        self.close()
