"""The scenario room: the scenario file's schema (``schema``: robot, object, trajectory,
grasps, options -> a Scenario and its PipelineRequest) and the YAML field readers it shares
with the batch SPEC (``fields``). Imported by ``cli`` and ``dataset``; imports the core only."""
