"""The live twin: projects, the TwinSystem, the RabbitMQ bridge, the PT/DT runtime and the twin's services."""
