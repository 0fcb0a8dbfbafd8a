"""Control-table items of serial servos: where an item lies, who may write it, its documented
range, its unit, and how its bytes read as a number — unsigned, two's complement (``signed``),
or sign-magnitude with the sign in bit ``sign_bit`` (Feetech: bit 15 for positions and speeds,
11 for the homing offset, 10 for load; feetech-sts-and-lerobot.md §1.4). A family keeps its
tables of these; the kit reads and writes them."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Item:
    address: int
    size: int
    name: str
    access: str = "RW"  # "R" or "RW"
    default: int = 0
    signed: bool = False  # two's complement
    low: int | None = None  # the documented range (None: only the encoding's)
    high: int | None = None
    # a safety setting (a limit, what an error does, where zero is, how the servo moves):
    # `config restore` writes it only when named with --allow
    safety: bool = False
    sign_bit: int | None = None  # sign-magnitude: the bit that holds the sign
    unit: str | None = None  # of one raw step ("0.088°"), when the table knows it
    big_endian: bool = False  # Feetech SCS; Dynamixel and Feetech STS are little-endian

    @property
    def key(self) -> str:
        """The name --allow takes: max-position-limit."""
        return self.name.lower().replace(" ", "-")

    @property
    def encoding(self) -> str:
        if self.sign_bit is not None:
            return "sign-magnitude"
        return "two's complement" if self.signed else "unsigned"

    def in_range(self, value: int) -> bool:
        """Whether ``value`` lies in the documented range (where the table gives one)."""
        return (self.low is None or value >= self.low) and (self.high is None
                                                             or value <= self.high)

    def span(self) -> tuple[int, int]:
        """The least and greatest values the encoding holds."""
        bits = self.size * 8
        if self.sign_bit is not None:
            top = (1 << self.sign_bit) - 1
            return -top, top
        if self.signed:
            return -(1 << (bits - 1)), (1 << (bits - 1)) - 1
        return 0, (1 << bits) - 1

    def encode(self, value: int) -> bytes:
        """The item's bytes for ``value``; OverflowError when the encoding cannot hold it."""
        order = "big" if self.big_endian else "little"
        if self.sign_bit is not None:
            low, high = self.span()
            if not low <= value <= high:
                raise OverflowError(f"{value} does not fit {self.name} ({self.encoding}, sign "
                                    f"in bit {self.sign_bit})")
            raw = -value | 1 << self.sign_bit if value < 0 else value
            return raw.to_bytes(self.size, order)
        return value.to_bytes(self.size, order, signed=self.signed)

    def decode(self, data: bytes | bytearray, offset: int = 0) -> int:
        """The value of the item's bytes at ``offset`` of ``data`` (a reply or a whole
        table)."""
        raw = data[offset:offset + self.size]
        if len(raw) != self.size:
            raise ValueError(f"{self.name} takes {self.size} byte(s), not {len(raw)}")
        order = "big" if self.big_endian else "little"
        if self.sign_bit is not None:
            value = int.from_bytes(raw, order)
            magnitude = value & ((1 << self.sign_bit) - 1)
            return -magnitude if value >> self.sign_bit & 1 else magnitude
        return int.from_bytes(raw, order, signed=self.signed)

    def of_table(self, table: bytes | bytearray, base: int = 0) -> int:
        """The item's value in a table read from address ``base`` on."""
        return self.decode(table, self.address - base)


def item_at(address: int, table: tuple[Item, ...]) -> Item | None:
    """The item holding byte ``address`` of a table."""
    return next((i for i in table if i.address <= address < i.address + i.size), None)
