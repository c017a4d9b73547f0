"""The ranking service: a request checked and converted into the core's PipelineRequest
(ranking_inputs), run under the fair compute lock and watched for its client (ranking_job,
clients), its response built and checked (response, message_checks), and why it may be refused
(errors)."""
