"""How a polling loop, parked until the board changes, is told from a loop that counts its turns, which runs on as on
the chip: the places the firmware read a register again from since the last change, and its variables there.

The rule runs where the firmware runs: on the board's MCU (`PIC18F8680._read_again`), or in the grader's sandbox.
"""
from __future__ import annotations

import opcode
import sys
from collections.abc import Callable
from types import CodeType, FrameType, FunctionType, GetSetDescriptorType, MemberDescriptorType
from typing import Any

POLLING_SITES = 1024        # (register, call site) a polling loop's reads are told apart by, at most, per change on the
                            # board: reads from further sites (a deep recursion's) never park
COUNTED_TURNS = 1024        # reads again in a new state (a turn of CANIsRxReady() makes two) that loops that count may
                            # make per change on the board, or per look, as on the chip; then they park as polling does
LOOK_PASSES = 64            # reads again elsewhere a looked-at loop may make on its way back to where it was woken
FROZEN_DEPTH = 3            # lists in lists (a queue of frames, an array of structs) are compared this deep
FROZEN_ITEMS = 256          # items of a list or a dict compared one by one, at most; a longer one by its length
FROZEN_BUDGET = 4096        # items one survey of the variables takes in, at most; the rest counts as unchanged
FROZEN_FRAMES = 8           # the innermost firmware frames whose variables are looked at (the outer ones wait for them)
KEPT_MOST = 4096            # code objects, modules and classes the tables below remember (the rest are read anew)
SPARSE_DICT_BYTES = 16384   # a dict that takes more room (dict.__sizeof__) is compared by its size: 256 items take 9 kB
CLASS_ITEMS = 1024          # a class whose namespaces (its own and its bases') hold more is compared by its kind
CLASS_LINEAGE = 64          # ... as is one with more bases in its method resolution order


# id(code object) -> FIRMWARE, KIT or ENTRY; id(code object) -> the names of data it reads from its module; id(module
# globals) -> the names its functions assign. Each code object and module kept alive in `_KEPT` so its id stays its
# own. Keyed by id: a code object's own hash is recomputed from its whole content on every call.
FIRMWARE, KIT, ENTRY = 0, 1, 2
_KINDS: dict[int, int] = {}
_DATA_GLOBALS: dict[int, tuple[str, ...]] = {}
_ASSIGNED: dict[int, frozenset[str]] = {}
_KEPT: list[object] = []
_ENTRIES: set[CodeType] = set()


def firmware_entry(function: Callable[..., object]) -> None:
    """Mark `function` as what calls a firmware's main(): the walk of `firmware_site` stops there."""
    _ENTRIES.add(function.__code__)
    forget_firmware_code()


def firmware_site(depth: int = 2, *, variables: bool = False) -> int:
    """Where in the firmware (outside this package) the current register access comes from, as a number: its call
    stack up to its main(), each firmware frame's code object and instruction offset, hashed. A polling loop reads from
    one place. With `variables`, what the firmware holds instead of where it is: the variables of its FROZEN_FRAMES
    innermost frames (`frame_variables`). The walk starts `depth` frames up (2: the caller of the function that calls
    this, the register read itself): each frame it looks at that had no frame object is given one, which costs more
    than the rest of it."""
    frame: FrameType | None = sys._getframe(depth)
    kinds = _KINDS
    site, frames, survey = 0, FROZEN_FRAMES, _Survey() if variables else None
    while frame is not None:
        code = frame.f_code
        kind = kinds.get(id(code))
        if kind is None:
            kind = _kind(frame, code)
        if kind == FIRMWARE:
            if not variables:
                site = hash((site, id(code), frame.f_lasti))
            elif frames:
                assert survey is not None
                site = hash((site, id(code), frame_variables(frame, survey)))
                frames -= 1
            else:
                break
        elif kind == ENTRY:
            break
        frame = frame.f_back
    return site


def _kind(frame: FrameType, code: CodeType) -> int:
    """Whether `code` is the firmware's, the kit's, or what calls a firmware's main(); kept for its next time."""
    name = dict.get(frame.f_globals, "__name__")        # (not .get, .startswith: a firmware's own may run)
    kit = type(name) is str and str.startswith(name, "appsim.")
    return _remember(_KINDS, code, ENTRY if code in _ENTRIES else KIT if kit else FIRMWARE)


def _remember(table: dict[int, Any], owner: object, value: Any) -> Any:
    """`value` kept in `table` for `owner`, and `owner` kept alive so that its id stays its own; as long as the tables
    hold fewer than KEPT_MOST owners (a firmware that makes code or classes at each turn has them read anew)."""
    if len(_KEPT) < KEPT_MOST:
        table[id(owner)] = value
        _KEPT.append(owner)
    return value


def forget_firmware_code() -> None:
    """Empty the caches behind `firmware_site` (new firmware brings new code objects)."""
    _KINDS.clear()
    _DATA_GLOBALS.clear()
    _CLASSES.clear()
    _ASSIGNED.clear()
    _KEPT.clear()


class PollingLoop:
    """The places a loop read registers again from, with nothing changed on the board since the firmware last read
    them: one read again from a place it read again from before is a polling loop's, to park. Unless the loop counts:
    a loop seen with new variables at each turn (`for (t = 0; t < 1000; t++) if (RXB0CONbits.RXFUL) break;`) is let
    turn on, COUNTED_TURNS reads at most per change; with its variables as they were, it parks.

    Comparing variables costs more than a register read, so it is done only where a loop was seen counting. Whether a
    loop that stays parked counts after all is found by a look: the board wakes it with nothing changed (`woken`),
    and its variables when it is back at that read tell; a loop that leaves instead (its count ran out) counted."""

    def __init__(self) -> None:
        self.sites: set[tuple[int, int]] = set()        # (address, site) read again from since the last change
        self.counting: set[tuple[int, int]] = set()     # (address, site) where a loop was seen counting
        self.counted = 0                                 # reads again of counting loops since the last change
        self.look: _Look | None = None                  # a look in progress (`woken`); a new place ends it

    def changed(self) -> None:
        """The board changed: every place is new again."""
        if self.look is not None:
            self.end_look()
        self.sites, self.counted = set(), 0

    def new_site(self, site: tuple[int, int]) -> bool:
        """Whether the loop has not read from `site` (address, place) since the last change; it has now, if there is
        room (a loop that reads from more places never parks). A look in progress ends there (`end_look`)."""
        sites = self.sites
        if site in sites:
            return False
        if len(sites) < POLLING_SITES:
            sites.add(site)
        if self.look is not None:
            self.end_look()
        return True

    def end_look(self) -> None:
        """The look in progress ends with the loop elsewhere than where it was woken (a new place, a change on the
        board): it left the way it polled, its count run out. Where it was woken and the places it passed count."""
        assert self.look is not None
        look, self.look = self.look, None
        self._count(look.passed | {look.at})

    def goes_on(self, address: int, place: int) -> int | None:
        """A read again of `address` from `place` (`firmware_site`) with nothing changed on the board since: the site
        the read counts as if the loop turns on (a place new since the change; or a counting loop's place, with its
        variables new there), None if it is a polling loop to park."""
        if self.new_site((address, place)):
            return place
        return self.from_known_place(address, place)

    def from_known_place(self, address: int, place: int, *, judged: bool = True) -> int | None:
        """`goes_on` for a read again from a place the loop read again from since the change (the board calls this
        itself, after its own look at `sites`: it is every polling loop's path). Not `judged`: the firmware runs
        elsewhere (the sandbox), which judges its variables itself and names a counting loop's read by a site new
        here."""
        if self.look is None and (not judged or (address, place) not in self.counting):
            return None                         # a polling loop, as it mostly is
        here = (address, place)
        look = self.look
        if look is not None:
            if here != look.at and look.passes:   # on to where the look woke it: it parks there, if it parks
                look.passes -= 1
                look.passed.add(here)
                return place
            self.look = None
            if judged and here == look.at:
                if firmware_site(variables=True) == look.variables:
                    self.counting.discard(here)     # it polls there after all
                    return None
                self._count(look.passed | {here})  # every place of the loop counts
        return self._turn(address, place) if judged and here in self.counting else None

    def _count(self, places: set[tuple[int, int]]) -> None:
        if len(self.counting) + len(places) > POLLING_SITES:
            self.counting.clear()
        self.counting |= places

    def _turn(self, address: int, place: int) -> int | None:
        """A counting loop's read again: the site it counts as (its place and variables), unless it was there in that
        state since the change (then it polls after all) or has used its turns."""
        if self.counted >= COUNTED_TURNS:
            return None
        site = hash((place, firmware_site(variables=True)))
        if not self.new_site((address, site)):
            return None
        self.counted += 1
        return site

    def mark(self) -> tuple[int, _Look | None, set[tuple[int, int]]]:
        """What a read again may change here, to `restore` if it turns out to have been none (in the sandbox, the
        board may change before the read it asks for)."""
        look = self.look
        return self.counted, None if look is None else look.copy(), set(self.counting)

    def restore(self, mark: tuple[int, _Look | None, set[tuple[int, int]]]) -> None:
        self.counted, self.look, self.counting = mark

    def woken(self, address: int, place: int, *, judged: bool = True) -> None:
        """The loop parked at its read of `address` from `place` was woken with nothing changed, to see whether it
        counts: it goes on to that place again (LOOK_PASSES reads again elsewhere at most), and its variables there
        are compared with those now. Until then that place counts: a loop that leaves it (its count ran out there)
        did. A loop that counts has turns again."""
        self.look = _Look((address, place), firmware_site(variables=True) if judged else 0)
        self.counted = 0
        if judged:
            self._count({(address, place)})


class _Look:
    """Where a look woke a parked loop (address, place), its variables then, and the places it passed since."""

    __slots__ = ("at", "passed", "passes", "variables")

    def __init__(self, at: tuple[int, int], variables: int):
        self.at, self.variables = at, variables
        self.passed: set[tuple[int, int]] = set()
        self.passes = LOOK_PASSES

    def copy(self) -> _Look:
        copy = _Look(self.at, self.variables)
        copy.passed, copy.passes = set(self.passed), self.passes
        return copy


def frame_variables(frame: FrameType, survey: _Survey) -> tuple[object, ...]:
    """A firmware frame's variables, as values equal only when nothing in them changed: its locals, and the module
    globals its code names that can change (`_frozen`, within what is left of the `survey`)."""
    code, module = frame.f_code, frame.f_globals
    names = _DATA_GLOBALS.get(id(code))
    if names is None:
        names = _data_globals(module, code)
    local = frame.f_locals              # a class body's namespace may be the firmware's mapping (__prepare__)
    return tuple([_frozen(value, survey) for value in (*(dict.values(local) if issubclass(type(local), dict) else ()),
                                                         *(dict.get(module, name) for name in names))])


_PLAIN = frozenset(map(id, (int, bool, str, bytes, float, complex, type(None))))   # by id: a type's hash may be its
                                                                                   # metaclass's, the firmware's code
_STORES_GLOBAL = frozenset({opcode.opmap["STORE_GLOBAL"], opcode.opmap["DELETE_GLOBAL"]})
_EXTENDED_ARG = opcode.opmap["EXTENDED_ARG"]


def _data_globals(module: dict[str, Any], code: CodeType) -> tuple[str, ...]:
    """The module globals `code` names that can change: one a function of the module assigns (a global counter), or a
    list, an array it fills, a dict or an object of the firmware's own class whose values it changes."""
    assigned = _assigned_globals(module)
    return _remember(_DATA_GLOBALS, code, tuple(
        name for name in code.co_names if dict.__contains__(module, name)
        and (name in assigned or _container(dict.__getitem__(module, name)))))


def _container(value: Any) -> bool:
    """Whether a global holds data whose contents can change: a list, an array, a dict, an object of the firmware's
    own class, or such a class."""
    kind = type(value)
    return (issubclass(kind, (list, bytearray, dict)) or _class_of(kind)[0] == _FROM_FIRMWARE
            or (kind is type and _class_of(value)[0] == _FROM_FIRMWARE))     # (a class: State.count += 1)


def _assigned_globals(module: dict[str, Any]) -> frozenset[str]:
    """The global names the module's functions assign (`global count; count += 1`), once per module."""
    found = _ASSIGNED.get(id(module))
    if found is None:
        names: set[str] = set()
        codes = [value.__code__ for value in dict.values(module)
                 if type(value) is FunctionType and value.__globals__ is module]
        while codes:
            each = codes.pop()
            names.update(_stored_globals(each))
            codes += [const for const in each.co_consts if isinstance(const, CodeType)]
        found = _remember(_ASSIGNED, module, frozenset(names))
    return found


def _stored_globals(code: CodeType) -> list[str]:
    """The globals `code` stores or deletes, read from its bytecode (2-byte units: opcode, argument; dis would take
    20 times as long, and a classroom loads a few hundred firmware modules)."""
    raw = code.co_code
    if not _STORES_GLOBAL & set(raw[::2]):
        return []
    names, extended = [], 0
    for k in range(0, len(raw), 2):
        opcode, argument = raw[k], raw[k + 1] | extended
        extended = argument << 8 if opcode == _EXTENDED_ARG else 0
        if opcode in _STORES_GLOBAL:
            names.append(code.co_names[argument])
    return names


class _Survey:
    """One survey of a firmware's variables: how many items it may still take in, and the lists it took in already (a
    list shared by many, `[[0] * 3000] * 3000`, is taken in once)."""

    __slots__ = ("left", "seen")

    def __init__(self) -> None:
        self.left = FROZEN_BUDGET
        self.seen: dict[int, object] = {}


_UNSEEN = "(not surveyed)"              # what is past a survey's budget or depth: the same every time
_OTHER = "(compared by kind only)"      # any other object: the same every time, whatever its identity
_KIT = "(the kit's)"                    # an object of the kit's own: the board's state is no firmware's variable
_NAN = "(NaN)"
_UNSET = "(not set)"                    # a slot of an object, before anything was stored in it


def compared_by_slots(kind: type) -> None:
    """Compare the kit's own slotted `kind` (the C runtime's pointer) by what its slots hold, its bases' included."""
    _BY_SLOTS[id(kind)] = tuple(name for each in reversed(kind.__mro__) for name in vars(each).get("__slots__", ()))
    _KEEP_KINDS.append(kind)


_BY_SLOTS: dict[int, tuple[str, ...]] = {}      # by id, as _PLAIN: the names of the slots
_KEEP_KINDS: list[type] = []                    # so that each id stays its kind's


def _frozen(value: Any, survey: _Survey, depth: int = 0) -> object:
    """`value` as something hashable that changes when its contents do, without running any of the firmware's own
    code (its __hash__, __iter__, properties, metaclass): the plain values as they are, a list (a C array, struct or
    variable whose address is taken, a queue) or a tuple (a CANMessage) by its items, a dict by its items, an object
    of the firmware's own class by its attributes and the class by its namespace (`State.count`), the kit's own
    slotted types by their slots; the kit's other objects and any other object by its kind only, so that an object
    made again at each turn (a generator) is no change, and the survey is the same in every run."""
    kind = type(value)
    if id(kind) in _PLAIN:
        return _NAN if (kind is float or kind is complex) and value != value else value    # a NaN's hash is its
    if survey.left <= 0 or depth >= FROZEN_DEPTH:                                           # identity's
        return _UNSEEN
    if issubclass(kind, (list, tuple, bytearray)):
        known = survey.seen.get(id(value))
        if known is not None:
            return known
        base = list if issubclass(kind, list) else bytearray if issubclass(kind, bytearray) else tuple
        size = base.__len__(value)      # before anything is copied: a list of millions is compared by its size
        if size > FROZEN_ITEMS:
            frozen: object = (_UNSEEN, size)
        elif base is bytearray:
            frozen = bytes(memoryview(value))
        else:
            items = list.copy(value) if base is list else tuple.__getitem__(value, slice(None))
            frozen = tuple([_frozen(item, survey, depth + 1) for item in items])
        survey.left -= size + 1
        survey.seen[id(value)] = frozen
        return frozen
    if issubclass(kind, int):           # an IntEnum's member, a flag
        return int.__index__(value)
    named = _BY_SLOTS.get(id(kind))
    if named is not None:
        survey.left -= 1
        return tuple([_frozen(getattr(value, name, None), survey, depth + 1) for name in named])
    origin, attributes, slots = _class_of(kind)
    if origin == _FROM_KIT:
        return _KIT
    if issubclass(kind, dict):
        return _frozen_items(value, value, survey, depth)
    if origin == _FROM_FIRMWARE and (attributes is not None or slots):
        return _frozen_object(value, kind, attributes, slots, survey, depth)
    if kind is type:                    # a class, by where it comes from
        origin = _class_of(value)[0]
        if origin == _FROM_KIT:
            return _KIT
        if origin == _FROM_FIRMWARE:    # by what its namespace holds (State.count += 1)
            return _frozen_items(value, value.__dict__, survey, depth)
    return _OTHER


def _frozen_object(value: object, kind: type, attributes: GetSetDescriptorType | None,
                   slots: tuple[tuple[str, MemberDescriptorType], ...], survey: _Survey, depth: int) -> object:
    """An object of the firmware's own class by its attributes: those in its __dict__ and those in its slots (a slot
    not set yet as such)."""
    namespace: Any = {}
    if attributes is not None:
        try:
            namespace = attributes.__get__(value, kind)
        except TypeError:               # the __dict__ of another class
            return _OTHER
        if type(namespace) is not dict:
            return _OTHER
    if slots and not _too_big(namespace):
        namespace = dict.copy(namespace)
        for name, slot in slots:
            try:
                namespace[name] = slot.__get__(value, kind)
            except AttributeError:
                namespace[name] = _UNSET
    return _frozen_items(value, namespace, survey, depth)


def _frozen_items(owner: object, items: Any, survey: _Survey, depth: int) -> object:
    """A dict (an object's attributes, a class's namespace) by its items, keys and values frozen; by its kind only if
    it holds one of the kit's objects (`vars()` of the kit's MCU: the board's state, which changes as it runs); by
    its size if it holds more than FROZEN_ITEMS items or the room of many more (a dict emptied by deletions is read
    slot by slot). `items` is a dict or a class's mappingproxy: nothing of the firmware's runs in them."""
    known = survey.seen.get(id(owner))
    if known is not None:
        return known
    plain = issubclass(type(items), dict)   # (a dict of the firmware's own class too: dict's methods, not its)
    size = dict.__len__(items) if plain else len(items)
    if (plain and _too_big(items)) or size > FROZEN_ITEMS:
        frozen: object = (_UNSEEN, size)
    else:
        pairs = [(_frozen(key, survey, depth + 1), _frozen(item, survey, depth + 1))
                 for key, item in (dict.items(items) if plain else items.items())]
        frozen = _OTHER if any(key is _KIT or item is _KIT for key, item in pairs) else tuple(pairs)
    survey.left -= size + 1
    survey.seen[id(owner)] = frozen
    return frozen


def _too_big(items: dict[Any, Any]) -> bool:
    """Whether a dict is compared by its size: more than FROZEN_ITEMS items, or the room of many more (a dict
    emptied by deletions is read slot by slot)."""
    return dict.__len__(items) > FROZEN_ITEMS or dict.__sizeof__(items) > SPARSE_DICT_BYTES


def _class_of(kind: type) -> _Class:
    """Where the class `kind` comes from, and what gives its objects their attributes: the __dict__ Python gives a
    class's objects (None if they have none of that kind) and their slots; read once (`_read_class`)."""
    found = _CLASSES.get(id(kind))
    if found is None:
        found = _remember(_CLASSES, kind, _read_class(kind))
    return found


def _read_class(kind: type) -> _Class:
    """`_class_of`, read as type reads a class, item by item, so that no key of its namespace is compared (its __eq__
    would run): the firmware's or the kit's if a class statement made it (no metaclass), by its module; anything else
    is Python's (a C type, one with a metaclass, a namespace too big to read)."""
    if type(kind) is not type or not kind.__flags__ & _HEAP_TYPE:
        return _FROM_PYTHON, None, ()   # (its metaclass is type: what follows reads it as type does)
    lineage = kind.__mro__
    if len(lineage) > CLASS_LINEAGE or sum(len(each.__dict__) for each in lineage) > CLASS_ITEMS:
        return _FROM_PYTHON, None, ()
    module: object = None
    attributes: Any = None
    slots: list[tuple[str, MemberDescriptorType]] = []
    for each in lineage:
        for key, item in each.__dict__.items():
            if type(key) is not str:
                continue
            # Python's own descriptors, of the class that brought them, not any C descriptor put there
            own = type(item) in (GetSetDescriptorType, MemberDescriptorType) and item.__objclass__ is each and (
                type(item.__name__) is str and str.__eq__(item.__name__, key))
            if module is None and each is kind and str.__eq__(key, "__module__"):
                module = item
            elif attributes is None and str.__eq__(key, "__dict__"):
                attributes = item if own and type(item) is GetSetDescriptorType else False
            elif own and type(item) is MemberDescriptorType:
                slots.append((key, item))
    if type(module) is not str:
        return _FROM_PYTHON, None, ()
    return (_FROM_KIT if str.startswith(module, "appsim.") else _FROM_FIRMWARE), attributes or None, tuple(slots)


_FROM_PYTHON, _FROM_KIT, _FROM_FIRMWARE = range(3)
_Class = tuple[int, GetSetDescriptorType | None, tuple[tuple[str, MemberDescriptorType], ...]]
_CLASSES: dict[int, _Class] = {}        # id(class) -> `_class_of`
_HEAP_TYPE = 1 << 9                     # Py_TPFLAGS_HEAPTYPE: a class made by a class statement (or type())
