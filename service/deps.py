"""FastAPI dependencies as Annotated aliases."""

from __future__ import annotations

from typing import Annotated

from fastapi import Depends, Request

from service.bootstrap import Container
from service.states import StateReader


def get_container(request: Request) -> Container:
    """The container the app was built with."""
    container: Container = request.app.state.container
    return container


def get_states(request: Request) -> StateReader:
    """The app's state reader (snapshot + tail, with a small cache)."""
    reader: StateReader = request.app.state.states
    return reader


ContainerDep = Annotated[Container, Depends(get_container)]
StatesDep = Annotated[StateReader, Depends(get_states)]
