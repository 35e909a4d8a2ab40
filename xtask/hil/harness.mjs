// The bench's harness: a Raspberry Pi Pico (RP2040) emulated by rp2040js, driven by
// `cargo xtask hil` over stdin and stdout, one JSON object a line.
//
// It only moves pin levels and time. The world (where the robot is, what the sonar sees,
// when a bump switch closes) is the project's Rust world in the xtask process; this file
// boots the firmware's flash image, applies the input levels the world schedules (or what an
// open input's pad gives it), reports the output pins' edges and the PWM duties measured from
// them, and reads what the firmware writes to RAM: its defmt log over RTT (the flight
// recording in it), and its sensors' health block, a diagnostic the bench judges nothing by.
// It also counts cycles: each
// interrupt handler's own, thread mode's busy stretches and the critical sections, for the
// response-time analysis; the back edges of the loops `cargo xtask wcet` takes bounds of on
// trust (the boot command's `loops`), the most of each on one entry; and each call of the
// functions the boot command's `timed` lists (the control loop's decisions), from its entry
// to its return, handlers excluded.
//
// Commands (xtask -> harness):
//   {"cmd":"boot","flash":PATH,"symbols":{...},"code":[FROM,TO],"health_words":N,"outputs":[..],
//    "pwm":[..],"inputs":{pin:level}}            the flash image (from 0x1000_0000), where its
//                                                RTT block, health block and test points are,
//                                                and where its code runs (SRAM on the Pico)
//   {"cmd":"set","pin":P,"level":0|1|null,"at":NS}  an input driven low or high from NS on (NS >=
//                                                now), or left open (null): it then reads what
//                                                its pad gives it (see "Pads" below)
//   {"cmd":"run","until":NS}                     runs until NS or until something happens
//   {"cmd":"inject","what":"panic"|"hang"}       thread mode calls that test point next
//   {"cmd":"stats"}                              the cycle accounts so far
//   {"cmd":"stack","from":A,"to":B}              bytes of the stack [A, B) used: below B, down to
//                                                the lowest word no longer 0xcccccccc (the paint)
//   {"cmd":"call","function":F,"args":[..]}      calls the function at F (before any `run`) with
//                                                up to four words in r0-r3, to its return; says
//                                                {"ev":"returned","cycles":N,"r0":..,"r1":..}
//                                                (for `cargo xtask wcet --emulated`)
//   {"cmd":"quit"}
// Events (harness -> xtask), each with the emulated time `ns`:
//   {"ev":"pin","pin":P,"level":L}      an output's edge (a pin no longer driven reads 0)
//   {"ev":"duty","pin":P,"permille":D}  a PWM output's duty, when it changes
//   {"ev":"health","words":[...]}       the firmware's PSMPA_HEALTH block, when it changes
//   {"ev":"rtt","data":HEX}          bytes of the defmt log
//   {"ev":"reset","cause":"watchdog"}   the watchdog fired: the chip was reset, the world kept
//   {"ev":"warning","message":M,"pc":PC} rp2040js warned (an access to unmapped memory, an
//                                       unimplemented register or instruction), not one of the
//                                       registers silicon has and the emulator does not model
//   {"ev":"at"}                         the run stopped here (after its events)
//
// rp2040js's pitfalls, and what this file does about them (boards/README.md, "What the bench
// verifies"):
// * SEV is a no-op: embassy's thread executor needs it, so the logger's "SEV" message sets
//   the core's event flag.
// * A watchdog that fired fires again at the same instant for ever: the harness stops it and
//   resets the chip itself (a new chip whose watchdog says it timed out, the same flash and
//   the same SRAM, as a reset leaves it).
// * The boot ROM's path halts: the image is started from its boot vectors after boot2 (VTOR,
//   SP, PC), which copy the code into SRAM; the ROM is zeros (the firmware calls no ROM
//   routine).
// * Inputs do not follow pull-ups: an input the world leaves open reads what its pad's
//   configuration (PADS_BANK0) gives it, resolved here: its pull-up, its pull-down, the level
//   it held under both (the bus keeper), or with neither a floating level: a seeded
//   pseudo-random level drawn again every millisecond, as a pin picking up noise.
// * Its warnings (an access to unmapped memory reads 0xffffffff where silicon raises a bus
//   fault) are reported, except for the registers that silicon has and rp2040js does not
//   model, listed in SILICON_ONLY with what they are.

import { createInterface } from 'node:readline';
import { readFileSync } from 'node:fs';
import { Simulator, GPIOPinState } from 'rp2040js';

const NS_PER_CYCLE = 8; // 125 MHz
const WATCHDOG = 0x40058; // its peripheral slot (address >> 12)
const WATCHDOG_REASON_TIMER = 1;
const SIO_SPINLOCK31 = 0x17c; // embassy-rp's critical section takes spinlock 31
const VECTOR_TABLE = 0x10000100; // after the 256 B second-stage bootloader
const EXC_HARDFAULT = 3;
/** The most cycles the copy into SRAM may take (16 bytes in about 14 cycles: 1 MB's worth). */
const BOOT_COPY_LIMIT = 1_000_000;
/** Where a `call` returns to (SRAM's scratch bank X, never run), and its stack's top. */
const RETURN = 0x20040000;
const CALL_STACK = 0x20042000;
const CALL_LIMIT = 1_000_000;
/** How often a floating input takes a new level, ns. */
const FLOAT_NS = 1_000_000;

/**
 * Registers that exist on the RP2040 and that rp2040js does not model (it warns and reads
 * zero): the firmware's accesses to them are its HAL's ordinary start-up, not faults.
 */
const SILICON_ONLY = new Set([
  'PPB read 0xd94', // MPU_TYPE: rp2040js has no MPU; the stack guard finds none and says so
  'ROSC_BASE write 0x0', // the ring oscillator's CTRL, FREQA, FREQB, DIV: clock set-up
  'ROSC_BASE write 0x4',
  'ROSC_BASE write 0x8',
  'ROSC_BASE write 0x10',
  'VREG_AND_CHIP_RESET_BASE read 0x0', // the regulator's VREG and the brown-out detector's BOD
  'VREG_AND_CHIP_RESET_BASE write 0x0',
  'VREG_AND_CHIP_RESET_BASE write 0x4',
]);

/** The key of an unimplemented register's warning in SILICON_ONLY, or null. */
function registerKey(component, message) {
  const m = /^Unimplemented peripheral (read from|write to) (0x[0-9a-f]+)/.exec(message);
  return m ? `${component} ${m[1] === 'read from' ? 'read' : 'write'} ${m[2]}` : null;
}

const out = (event) => process.stdout.write(JSON.stringify(event) + '\n');

/** Cycle accounts: per exception, thread mode's busy stretches, critical sections. */
class Accounts {
  constructor() {
    this.handlers = {}; // exception number -> {count, total, max, maxAt}
    this.thread = { count: 0, total: 0, max: 0, maxAt: 0 };
    this.critical = { thread: 0, handler: 0, maxAt: 0 };
    this.boot = 0; // the last boot's copy into SRAM
  }
  handler(n, cycles, at) {
    const h = (this.handlers[n] ??= { count: 0, total: 0, max: 0, maxAt: 0 });
    h.count++;
    h.total += cycles;
    if (cycles > h.max) {
      h.max = cycles;
      h.maxAt = at;
    }
  }
}

class Bench {
  constructor(config) {
    this.config = config;
    this.image = readFileSync(config.flash);
    this.base = 0; // ns of emulated time before the current chip booted
    // What the world does to each input: 0 or 1 driven, null open.
    this.inputs = new Map(Object.entries(config.inputs).map(([p, l]) => [Number(p), l]));
    this.noise = (BigInt(config.seed) ^ 0x5851f42d4c957f2dn) & 0xffffffffffffffffn;
    this.schedule = []; // [{at, pin, level}], sorted by at
    this.events = [];
    this.accounts = new Accounts();
    // Where the code runs (SRAM on the Pico): the halfwords `loopFn` and `timedAt` mark.
    [this.code, this.codeEnd] = config.code;
    this.watchLoops(config.loops ?? []);
    this.watchCalls(config.timed ?? []);
    this.boot(false);
  }

  get now() {
    return this.base + this.sim.clock.nanos;
  }

  /** A new chip at the current instant, running the flash image from its vector table. */
  boot(afterWatchdog) {
    const base = this.sim ? this.now : 0;
    // A watchdog reset leaves SRAM as it was (what `.uninit` keeps: the flight recorder's
    // ring); the new chip starts with the old one's.
    const sram = afterWatchdog && this.mcu ? this.mcu.sram.slice() : null;
    this.sim = new Simulator();
    this.base = base;
    const mcu = (this.mcu = this.sim.rp2040);
    if (sram) mcu.sram.set(sram);
    const core = (this.core = mcu.core);
    mcu.loadBootrom(new Uint32Array(4096));
    mcu.flash.set(this.image);
    mcu.logger = {
      debug() {},
      info: (_, message) => {
        if (message === 'SEV') core.eventRegistered = true;
      },
      warn: (component, message) => {
        if (SILICON_ONLY.has(registerKey(component, message))) return;
        this.events.push({ ev: 'warning', message: `${component}: ${message}`, pc: core.PC, ns: this.now });
      },
      error: (component, message) => this.events.push({ ev: 'error', component, message }),
    };
    // UDF and BKPT: rp2040js calls this hook (for a debugger) and runs on; a chip with no
    // debugger attached takes a HardFault, as the panic handler's `udf` expects.
    this.faulted = false;
    this.floated = new Set(); // inputs found floating on this chip
    mcu.onBreak = () => {
      this.faulted = true;
    };
    const watchdog = mcu.peripherals[WATCHDOG];
    if (afterWatchdog) watchdog.reason = WATCHDOG_REASON_TIMER;
    watchdog.onWatchdogTrigger = () => {
      // Fired once: stop it (rp2040js would fire it again at once, for ever) and reset.
      watchdog.alarm.enable = false;
      watchdog.timer.enable = false;
      this.resetRequested = true;
    };
    this.watchCycles(core);
    this.watchSpinlock(mcu);
    for (const pin of this.inputs.keys()) {
      // A pad's pull changed (the firmware configured it): an open input follows.
      mcu.gpio[pin].addListener(() => this.apply(pin));
      this.apply(pin);
    }
    this.floatAlarm = this.sim.clock.createAlarm(() => this.refloat());
    this.floatAlarm.schedule(FLOAT_NS);
    for (const pin of this.config.outputs) {
      mcu.gpio[pin].addListener((state) => this.output(pin, state));
      if (afterWatchdog) this.output(pin, GPIOPinState.Input);
    }
    this.pwm = new Map();
    for (const pin of this.config.pwm) {
      const p = { rise: null, fall: null, permille: null, quiet: null };
      this.pwm.set(pin, p);
      mcu.gpio[pin].addListener((state) => this.pwmEdge(pin, p, state));
      this.pwmQuiet(pin, p, 200_000);
    }
    core.VTOR = VECTOR_TABLE;
    core.SP = mcu.readUint32(VECTOR_TABLE);
    core.PC = mcu.readUint32(VECTOR_TABLE + 4) & ~1;
    this.copyToCode(core);
    this.rtt = null;
    this.healthSeen = -1;
    this.busySince = null;
    // A reset abandons every loop, and the timed calls, where they were.
    this.timing = [];
    for (const l of this.loops ?? []) l.count.fill(0);
  }

  /**
   * Runs the boot vectors' copy of the image into SRAM (in flash, interrupts off, no
   * peripheral touched) until the first instruction where the code runs, cortex-m-rt's reset
   * handler: its cycles are the boot's cost of running from SRAM (0 for code in flash). A
   * copy that never gets there is left to run on, and the run's checks find the dead chip.
   */
  copyToCode(core) {
    const start = core.cycles;
    while ((core.PC < this.code || core.PC >= this.codeEnd) && core.cycles - start < BOOT_COPY_LIMIT) {
      this.sim.clock.tick(core.executeInstruction() * NS_PER_CYCLE);
    }
    this.accounts.boot = core.cycles - start;
  }

  /**
   * The annotated loops of `cargo xtask wcet`, whose back edges are counted: per entry into a
   * loop (a jump into its body from the rest of its function, or a call of the function where
   * it starts in the loop) and per exception level (a handler's run of the loop is its own,
   * and the interrupted one goes on when it returns), the back edges taken (a latch to an
   * entry, or a latch call's return to one); the most of each, per exception level, is in
   * `stats`. `loopFn` marks each halfword of the code with its
   * function's index (from 1), so that an instruction outside them costs a lookup.
   */
  watchLoops(loops) {
    this.loops = loops.map((l) => ({
      bound: l.bound,
      start: l.function[0],
      entries: new Set(l.entries),
      latches: new Set(l.latches),
      returns: new Set(l.returns ?? []),
      body: new Set(l.body),
      count: new Int32Array(64),
      max: new Int32Array(64),
    }));
    this.loopFn = null;
    if (this.loops.length === 0) return;
    this.loopFn = new Uint16Array((this.codeEnd - this.code) >>> 1);
    this.fnLoops = [null];
    const byStart = new Map();
    for (const [i, l] of this.loops.entries()) {
      let idx = byStart.get(l.start);
      if (idx === undefined) {
        idx = this.fnLoops.length;
        byStart.set(l.start, idx);
        this.fnLoops.push([]);
        const [from, to] = loops[i].function;
        for (let a = from; a < to; a += 2) this.loopFn[(a - this.code) >>> 1] = idx;
      }
      this.fnLoops[idx].push(l);
    }
  }

  /**
   * The functions whose calls are timed: `timed[i]` is an entry address (0: none). `timedAt`
   * marks each entry's halfword of the code with i + 1; `calls` lists [i, own cycles] in order.
   */
  watchCalls(timed) {
    this.calls = [];
    this.timing = [];
    this.timedAt = new Uint8Array((this.codeEnd - this.code) >>> 1);
    for (const [i, at] of timed.entries()) {
      if (at >= this.code && at < this.codeEnd) this.timedAt[((at & ~1) - this.code) >>> 1] = i + 1;
    }
  }

  /**
   * After an instruction that went to `npc`: a timed call begins, or the innermost one timed
   * returns. Timed calls nest (a decision inside a poll of the control task): each counts its
   * callees, timed or not.
   */
  callStep(npc) {
    const core = this.core;
    const t = this.timing.at(-1);
    // Back at the caller, on its stack, at its exception level: the call is over.
    if (t !== undefined && npc === t.ret && core.SP === t.sp && core.IPSR === t.ctx) {
      const own = core.cycles - t.start - (this.handlerCycles - t.handlers);
      this.calls.push([t.i, own]);
      this.timing.pop();
      return;
    }
    const i = this.timedAt[(npc - this.code) >>> 1] | 0;
    if (i !== 0) {
      this.timing.push({
        i: i - 1,
        start: core.cycles,
        handlers: this.handlerCycles,
        ret: core.LR & ~1,
        sp: core.SP,
        ctx: core.IPSR,
      });
    }
  }

  /** One instruction from `pc` to `npc` at exception level `ctx`, in or into a loop's function. */
  loopStep(pc, npc, a, b, ctx) {
    for (const l of this.fnLoops[b || a]) {
      // A back edge: a latch to an entry, or, for a latch that is a call, its callee's
      // return to the entry after it (the call itself only leaves the loop's function).
      if ((l.latches.has(pc) && l.entries.has(npc)) || (a !== b && l.returns.has(npc))) {
        const c = ++l.count[ctx];
        if (c > l.max[ctx]) l.max[ctx] = c;
      } else if (!l.body.has(pc) && l.body.has(npc) && (a === b || npc === l.start)) {
        l.count[ctx] = 0;
      }
    }
  }

  /** A pseudo-random bit (xorshift64), the same sequence for the same seed. */
  bit() {
    let x = this.noise;
    x ^= (x << 13n) & 0xffffffffffffffffn;
    x ^= x >> 7n;
    x ^= (x << 17n) & 0xffffffffffffffffn;
    this.noise = x;
    return (x & 1n) === 1n;
  }

  /** An input's level: the world's drive, or what its pad gives an open pin. */
  apply(pin) {
    const gpio = this.mcu.gpio[pin];
    const drive = this.inputs.get(pin);
    let level;
    if (drive === 0 || drive === 1) level = drive === 1;
    else if (gpio.pullupEnabled && gpio.pulldownEnabled) level = gpio.rawInputValue; // bus keeper
    else if (gpio.pullupEnabled) level = true;
    else if (gpio.pulldownEnabled) level = false;
    else {
      // Floating: a seeded random level, and a defect of the board whatever it reads (the
      // pads reset with their pull-down, so only the firmware leaves an input without a pull).
      level = this.bit();
      if (!this.floated.has(pin)) {
        this.floated.add(pin);
        this.events.push({
          ev: 'warning',
          message: `GPIO${pin}: an input the world leaves open floats: its pad has neither a pull-up nor a pull-down`,
          pc: this.core.PC,
          ns: this.now,
        });
      }
    }
    if (level !== gpio.rawInputValue) gpio.setInputValue(level);
  }

  /** Floating inputs take a new level. */
  refloat() {
    for (const [pin, drive] of this.inputs) {
      const gpio = this.mcu.gpio[pin];
      if (drive === null && !gpio.pullupEnabled && !gpio.pulldownEnabled) this.apply(pin);
    }
    this.floatAlarm.schedule(FLOAT_NS);
  }

  output(pin, state) {
    const level = state === GPIOPinState.High ? 1 : 0;
    this.events.push({ ev: 'pin', pin, level, ns: this.now });
  }

  /** A PWM output's edge: the duty of the period that ends at a rise. */
  pwmEdge(pin, p, state) {
    const t = this.sim.clock.nanos;
    if (state === GPIOPinState.High) {
      if (p.rise !== null && p.fall !== null && p.fall > p.rise) {
        const period = t - p.rise;
        this.duty(pin, p, Math.round((1000 * (p.fall - p.rise)) / period));
        this.pwmQuiet(pin, p, 3 * period);
      }
      p.rise = t;
    } else {
      p.fall = t;
    }
  }

  /** A duty of 0 or 1,000 has no edges: a pin that stays put this long holds its level. */
  pwmQuiet(pin, p, after) {
    if (p.quiet) p.quiet.cancel();
    p.quiet = this.sim.clock.createAlarm(() => {
      const high = this.mcu.gpio[pin].value === GPIOPinState.High;
      this.duty(pin, p, high ? 1000 : 0);
      p.rise = null;
      p.fall = null;
      this.pwmQuiet(pin, p, after);
    });
    p.quiet.schedule(after);
  }

  duty(pin, p, permille) {
    if (permille !== p.permille) {
      p.permille = permille;
      this.events.push({ ev: 'duty', pin, permille, ns: this.now });
    }
  }

  /** Exclusive cycles of every handler, and thread mode's busy stretches between sleeps. */
  watchCycles(core) {
    const stack = []; // [{n, start, nested}]
    this.handlerCycles = 0; // every handler's cycles so far
    const entry = core.exceptionEntry.bind(core);
    const ret = core.exceptionReturn.bind(core);
    core.exceptionEntry = (n) => {
      stack.push({ n, start: core.cycles, nested: 0 });
      entry(n);
    };
    core.exceptionReturn = (excReturn) => {
      ret(excReturn);
      const top = stack.pop();
      if (!top) return;
      const all = core.cycles - top.start;
      const own = all - top.nested;
      this.accounts.handler(top.n, own, this.now);
      this.handlerCycles += own;
      if (stack.length) stack[stack.length - 1].nested += all;
      this.pollHealth();
    };
    this.exceptions = stack;
  }

  /** Critical sections: how long spinlock 31 is held, by the context that took it. */
  watchSpinlock(mcu) {
    const sio = mcu.sio;
    const read = sio.readUint32.bind(sio);
    const write = sio.writeUint32.bind(sio);
    let taken = null;
    sio.readUint32 = (offset) => {
      const v = read(offset);
      if (offset === SIO_SPINLOCK31 && v !== 0) {
        taken = { cycles: this.core.cycles, thread: this.core.IPSR === 0 };
      }
      return v;
    };
    sio.writeUint32 = (offset, value) => {
      write(offset, value);
      if (offset === SIO_SPINLOCK31 && taken) {
        const held = this.core.cycles - taken.cycles;
        const c = this.accounts.critical;
        const key = taken.thread ? 'thread' : 'handler';
        if (held > c[key]) {
          c[key] = held;
          if (taken.thread) c.maxAt = this.now;
        }
        taken = null;
      }
    };
  }

  readRtt() {
    const rttAt = this.config.symbols.rtt;
    if (rttAt === undefined) return;
    const v = this.mcu.sramView;
    const up = rttAt - 0x20000000 + 24; // the first up buffer, after the 16 B id and 2 counts
    const buffer = v.getUint32(up + 4, true) - 0x20000000;
    const size = v.getUint32(up + 8, true);
    const wr = v.getUint32(up + 12, true);
    let rd = v.getUint32(up + 16, true);
    if (rd === wr || size === 0) return;
    const bytes = [];
    while (rd !== wr) {
      bytes.push(this.mcu.sram[buffer + rd]);
      rd = (rd + 1) % size;
    }
    v.setUint32(up + 16, rd, true);
    // The log stops a run too: what the firmware says may end it (its task's outcome).
    this.events.push({ ev: 'rtt', data: Buffer.from(bytes).toString('hex'), ns: this.now });
  }

  pollHealth() {
    const at = this.config.symbols.health;
    if (at === undefined) return;
    const v = this.mcu.sramView;
    const changes = v.getUint32(at - 0x20000000, true);
    if (changes === this.healthSeen) return;
    this.healthSeen = changes;
    const words = [];
    for (let i = 0; i < this.config.health_words; i++) words.push(v.getUint32(at - 0x20000000 + 4 * i, true));
    this.events.push({ ev: 'health', words, ns: this.now });
  }

  /** Thread mode enters or leaves sleep: a busy stretch ends or begins. */
  sleeping(waiting) {
    const core = this.core;
    // What the firmware wrote before it slept, also the first time after a reset (when no
    // busy stretch was open): it may sleep for the rest of the run.
    if (waiting) {
      this.pollHealth();
      this.readRtt();
    }
    if (waiting && this.busySince !== null && core.IPSR === 0) {
      const busy = core.cycles - this.busySince.cycles - (this.handlerCycles - this.busySince.handlers);
      const t = this.accounts.thread;
      t.count++;
      t.total += busy;
      if (busy > t.max) {
        t.max = busy;
        t.maxAt = this.now;
      }
      this.busySince = null;
    } else if (!waiting && this.busySince === null) {
      this.busySince = { cycles: core.cycles, handlers: this.handlerCycles };
    }
  }

  inject(what) {
    const symbol = what === 'panic' ? this.config.symbols.test_panic : this.config.symbols.test_hang;
    this.injection = symbol;
  }

  run(until) {
    let core = this.core;
    let n = 0;
    let wasWaiting = core.waiting;
    while (this.now < until && this.events.length === 0) {
      while (this.schedule.length && this.schedule[0].at <= this.now) {
        const { pin, level } = this.schedule.shift();
        this.inputs.set(pin, level);
        this.apply(pin);
      }
      if (this.injection !== undefined && core.IPSR === 0 && !core.PM) {
        // Thread mode calls the test point now, abandoning what it was doing (never inside a
        // critical section: a behaviour stuck in a loop leaves interrupts on).
        core.PC = this.injection & ~1;
        core.waiting = false;
        this.injection = undefined;
      }
      if (core.waiting) {
        const clock = this.sim.clock;
        let step = until - this.now;
        if (this.schedule.length) step = Math.min(step, this.schedule[0].at - this.now);
        // To the next alarm (rp2040js keeps them in a list; one due now is a step of 0), so
        // that the core runs as soon as an alarm's interrupt wakes it.
        const next = clock.nextAlarm;
        if (next) step = Math.min(step, next.nanos - clock.nanos);
        clock.tick(Math.max(step, 0));
      } else {
        const pc = core.PC;
        const ctx = core.IPSR;
        this.sim.clock.tick(core.executeInstruction() * NS_PER_CYCLE);
        const npc = core.PC;
        const code = this.code;
        if (this.timing.length !== 0 || this.timedAt[(npc - code) >>> 1] > 0) {
          this.callStep(npc);
        }
        const loopFn = this.loopFn;
        if (loopFn !== null) {
          const a = loopFn[(pc - code) >>> 1] | 0;
          const b = loopFn[(npc - code) >>> 1] | 0;
          if ((a | b) !== 0 && core.IPSR === ctx) this.loopStep(pc, npc, a, b, ctx);
        }
        if (this.faulted) {
          this.faulted = false;
          if (core.IPSR === EXC_HARDFAULT) {
            // A fault in the HardFault handler locks a Cortex-M0+ up.
            this.events.push({ ev: 'error', message: 'lockup: a UDF or BKPT in the HardFault handler' });
          } else {
            // The stacked return address is the instruction's own, as on the chip.
            core.PC -= core.breakRewind;
            core.exceptionEntry(EXC_HARDFAULT);
          }
        }
        if ((++n & 255) === 0) {
          this.readRtt();
          this.pollHealth();
        }
      }
      if (core.waiting !== wasWaiting) {
        wasWaiting = core.waiting;
        this.sleeping(wasWaiting);
      }
      if (this.resetRequested) {
        this.resetRequested = false;
        this.readRtt();
        this.boot(true);
        core = this.core;
        wasWaiting = core.waiting;
        this.events.push({ ev: 'reset', cause: 'watchdog', ns: this.now });
      }
    }
    this.readRtt();
    for (const e of this.events) out(e);
    this.events = [];
    out({ ev: 'at', ns: this.now });
  }

  set(pin, level, at) {
    const item = { at: Math.max(at, this.now), pin, level };
    let i = this.schedule.length;
    while (i > 0 && this.schedule[i - 1].at > item.at) i--;
    this.schedule.splice(i, 0, item);
  }

  /** The stack's high-water mark: cortex-m-rt painted [from, to) before main. */
  stack(from, to) {
    const v = this.mcu.sramView;
    let at = from;
    while (at < to && v.getUint32(at - 0x20000000, true) === 0xcccccccc) at += 4;
    out({ ev: 'stack', used: to - at, ns: this.now });
  }

  /**
   * Calls the function at `fn` with `args` in r0-r3 on a stack of its own, from the chip as
   * booted, until it returns to RETURN (an address in SRAM it never runs): no clock, no
   * interrupt, only the instructions and their cycles.
   */
  call(fn, args) {
    const core = this.core;
    for (let i = 0; i < 4; i++) core.registers[i] = args[i] ?? 0;
    core.SP = CALL_STACK;
    core.LR = RETURN | 1;
    core.PC = fn & ~1;
    let cycles = 0;
    while (core.PC !== RETURN) {
      if (cycles > CALL_LIMIT || this.faulted) {
        out({ ev: 'error', message: `the call of ${fn.toString(16)} did not return in ${CALL_LIMIT} cycles` });
        return;
      }
      cycles += core.executeInstruction();
    }
    const [r0, r1] = core.registers;
    out({ ev: 'returned', cycles, r0, r1 });
  }

  stats() {
    out({
      ev: 'stats',
      ns: this.now,
      ...this.accounts,
      instructions_per_ns: this.core.cycles / this.now,
      loops: this.loops.map((l) => Array.from(l.max)),
      calls: this.calls,
    });
  }
}

let bench = null;
const lines = createInterface({ input: process.stdin });
lines.on('line', (line) => {
  let cmd;
  try {
    cmd = JSON.parse(line);
  } catch {
    out({ ev: 'error', message: `not JSON: ${line.slice(0, 80)}` });
    return;
  }
  switch (cmd.cmd) {
    case 'boot':
      bench = new Bench(cmd);
      out({ ev: 'at', ns: 0 });
      break;
    case 'set':
      bench.set(cmd.pin, cmd.level, cmd.at);
      break;
    case 'run':
      bench.run(cmd.until);
      break;
    case 'inject':
      bench.inject(cmd.what);
      break;
    case 'call':
      bench.call(cmd.function, cmd.args);
      break;
    case 'stats':
      bench.stats();
      break;
    case 'stack':
      bench.stack(cmd.from, cmd.to);
      break;
    case 'quit':
      process.exit(0);
      break;
    default:
      out({ ev: 'error', message: `unknown command ${cmd.cmd}` });
  }
});
