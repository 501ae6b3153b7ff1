"""The simulated world: the MuJoCo Panda scene (``panda_scene``), the ``SimWorld`` that implements
``mmact_ctrl.world.World`` (``sim_world``), target motions (``targets``), the scripted expert (``expert``), the camera
sensor (``camera_sensor``), the one factory that builds them from plain settings (``factory``), videos (``video``),
rendering off the loop (``render_worker``), MuJoCo's viewer (``viewer``) and the Gymnasium environment beside the
world (``gym_env``)."""
