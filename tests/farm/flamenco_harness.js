// SPDX-License-Identifier: GPL-3.0-or-later
//
// A stand-in for Flamenco Manager's job compiler, for tests: loads a job type script in a
// fresh `vm` context with the globals a Manager gives job types (written here from
// Flamenco's documentation and sources: author.Task/Command, job.addTask, frameChunker,
// frameCount, path, shellSplit, formatTimestampLocal, print, alert), compiles jobs and
// prints the task graphs as JSON. Commands are checked against the parameters the
// Worker requires (blender-render: exe, argsBefore, blendfile, args; frames-to-video:
// exe, fps, inputGlob, outputFile, args), as a Worker would reject them.
//
//   node flamenco_harness.js < request.json
//
// request: {"script": PATH, "jobs": [{"name", "settings", "created"}], "chunks": [[RANGE, SIZE]]}
// answer:  {"jobType": JOB_TYPE, "jobs": [{"error"} | {"tasks", "log"}], "chunks": [{"chunks"} | {"error"}]}

"use strict";

const fs = require("fs");
const nodePath = require("path").posix;
const vm = require("vm");

// --- frame ranges, as the Manager's frameChunker/frameCount treat them ------------------

function invalidRange(range, message) {
    return new Error(`invalid range "${range}": ${message}`);
}

// Frames of "1-10,20..25,40": sorted, each once. ".." is the same as "-".
function explodeFrames(range) {
    const regular = range.split("..").join("-");
    const frames = new Set();
    const parseInt10 = (text) => {
        const t = text.trim();
        if (!/^[+-]?\d+$/.test(t)) {
            throw invalidRange(regular, `not a number: "${text}"`);
        }
        return parseInt(t, 10);
    };
    for (const part of regular.split(",")) {
        const ends = part.split("-");
        if (ends.length === 1) {
            frames.add(parseInt10(ends[0]));
        } else if (ends.length === 2) {
            const start = parseInt10(ends[0]);
            const end = parseInt10(ends[1]);
            for (let f = start; f <= end; f++) {
                frames.add(f);
            }
        } else {
            throw invalidRange(regular, part);
        }
    }
    return Array.from(frames).sort((a, b) => a - b);
}

// Consecutive frames merged: runs of three or more as "A-B", shorter runs frame by frame.
function mergeFrames(frames) {
    const parts = [];
    const close = (from, to) => {
        if (from === to) {
            parts.push(`${from}`);
        } else if (from + 1 === to) {
            parts.push(`${from}`, `${to}`);
        } else {
            parts.push(`${from}-${to}`);
        }
    };
    let start = frames[0];
    let prev = frames[0];
    for (const frame of frames.slice(1)) {
        if (frame > prev + 1) {
            close(start, prev);
            start = frame;
        }
        prev = frame;
    }
    close(start, prev);
    return parts.join(",");
}

function frameChunker(range, chunkSize) {
    const text = String(range).trim();
    if (text === "") {
        throw invalidRange(text, "empty range");
    }
    if (!(chunkSize >= 1)) {
        throw new Error(`invalid chunk size, must be positive number: ${chunkSize}`);
    }
    const frames = explodeFrames(text);
    const chunks = [];
    for (let i = 0; i < frames.length; i += chunkSize) {
        chunks.push(mergeFrames(frames.slice(i, i + chunkSize)));
    }
    return chunks;
}

function frameCount(range) {
    return explodeFrames(String(range)).length;
}

// --- other globals ------------------------------------------------------------------------

// Shell-like splitting: whitespace separates words; quotes group; a backslash escapes.
function shellSplit(text) {
    const words = [];
    let word = null;
    let quote = null;
    for (let i = 0; i < text.length; i++) {
        const c = text[i];
        if (quote === "'") {
            if (c === "'") {
                quote = null;
            } else {
                word += c;
            }
        } else if (c === "\\" && quote !== "'") {
            if (i + 1 >= text.length) {
                throw new Error("EOF found after escape character");
            }
            word = (word === null ? "" : word) + text[++i];
        } else if (quote === '"') {
            if (c === '"') {
                quote = null;
            } else {
                word += c;
            }
        } else if (c === "'" || c === '"') {
            quote = c;
            word = word === null ? "" : word;
        } else if (/\s/.test(c)) {
            if (word !== null) {
                words.push(word);
                word = null;
            }
        } else {
            word = (word === null ? "" : word) + c;
        }
    }
    if (quote !== null) {
        throw new Error("EOF found when expecting closing quote");
    }
    if (word !== null) {
        words.push(word);
    }
    return words;
}

function formatTimestampLocal(date) {
    const d = new Date(date);
    const two = (n) => String(n).padStart(2, "0");
    return `${d.getFullYear()}-${two(d.getMonth() + 1)}-${two(d.getDate())}_` +
           `${two(d.getHours())}${two(d.getMinutes())}${two(d.getSeconds())}`;
}

const path = {
    basename: (p) => nodePath.basename(p),
    dirname: (p) => nodePath.dirname(p),
    join: (...parts) => nodePath.join(...parts.filter((p) => p !== "")),
    stem: (p) => nodePath.basename(p, nodePath.extname(p)),
};

// --- authoring ----------------------------------------------------------------------------

class Task {
    constructor(name, type) {
        this.name = name;
        this.type = type;
        this.commands = [];
        this.dependencies = [];
    }

    addCommand(command) {
        if (!(command instanceof Command)) {
            throw new Error("task.addCommand(): not a command made by author.Command()");
        }
        this.commands.push(command);
    }

    addDependency(task) {
        if (!(task instanceof Task)) {
            throw new Error("task.addDependency(): not a task made by author.Task()");
        }
        this.dependencies.push(task);
    }
}

class Command {
    constructor(name, parameters) {
        this.name = name;
        this.parameters = parameters;
    }
}

const isStrings = (v) => Array.isArray(v) && v.every((s) => typeof s === "string");
const isText = (v) => typeof v === "string" && v !== "";

// Parameters a Worker needs for each command it runs.
const COMMAND_PARAMETERS = {
    "blender-render": { exe: isText, argsBefore: isStrings, blendfile: (v) => typeof v === "string", args: isStrings },
    "frames-to-video": { exe: isText, fps: (v) => typeof v === "number" && v > 0, inputGlob: isText,
                         outputFile: isText, args: isStrings },
};

const author = {
    Task(name, type) {
        const n = String(name || "").trim();
        const t = String(type || "").trim();
        if (n === "") {
            throw new Error("author.Task(name, type): name is required");
        }
        if (t === "") {
            throw new Error("author.Task(name, type): type is required");
        }
        return new Task(n, t);
    },
    Command(name, parameters) {
        const wanted = COMMAND_PARAMETERS[name];
        if (wanted === undefined) {
            throw new Error(`author.Command(): no Worker command '${name}' in this harness`);
        }
        for (const key of Object.keys(wanted)) {
            if (!wanted[key](parameters[key])) {
                throw new Error(`author.Command('${name}'): parameter '${key}' missing or of the wrong type`);
            }
        }
        return new Command(name, parameters);
    },
};

// --- running a job type -------------------------------------------------------------------

function loadJobType(source, filename, log) {
    const context = vm.createContext({
        author, path, frameChunker, frameCount, shellSplit, formatTimestampLocal,
        print: (...args) => log.push(args.map(String).join(" ")),
        alert: (...args) => log.push("ALERT " + args.map(String).join(" ")),
    });
    // The Manager compiles job types in strict mode.
    vm.runInContext('"use strict";' + source, context, { filename });
    return context;
}

function messageOf(err) {
    if (err instanceof Error || (err && typeof err.message === "string")) {
        return err.message;
    }
    return String(err);
}

function compile(source, filename, job) {
    const log = [];
    const context = loadJobType(source, filename, log);
    const tasks = [];
    const authored = {
        name: job.name || "test job",
        created: new Date(job.created || "2026-01-02T03:04:05Z"),
        settings: JSON.parse(JSON.stringify(job.settings || {})),
        metadata: job.metadata || {},
        addTask(task) {
            if (!(task instanceof Task)) {
                throw new Error("job.addTask(): not a task made by author.Task()");
            }
            tasks.push(task);
        },
    };
    try {
        context.compileJob(authored);
    } catch (err) {
        return { error: messageOf(err), log };
    }
    const names = tasks.map((t) => t.name);
    return {
        log,
        settings: authored.settings,
        tasks: tasks.map((t) => ({
            name: t.name,
            type: t.type,
            commands: t.commands.map((c) => ({ name: c.name, parameters: c.parameters })),
            // A dependency on a task that was never added would never run.
            dependencies: t.dependencies.map((d) => (names.indexOf(d.name) >= 0 ? d.name : `<not added: ${d.name}>`)),
        })),
    };
}

function main() {
    const request = JSON.parse(fs.readFileSync(0, "utf8"));
    const answer = { jobs: [], chunks: [] };
    if (request.script) {
        const source = fs.readFileSync(request.script, "utf8");
        const context = loadJobType(source, request.script, []);
        answer.jobType = vm.runInContext("JOB_TYPE", context);
        answer.hasCompileJob = vm.runInContext("typeof compileJob", context) === "function";
        for (const job of request.jobs || []) {
            answer.jobs.push(compile(source, request.script, job));
        }
    }
    for (const [range, size] of request.chunks || []) {
        try {
            answer.chunks.push({ chunks: frameChunker(range, size) });
        } catch (err) {
            answer.chunks.push({ error: messageOf(err) });
        }
    }
    process.stdout.write(JSON.stringify(answer));
}

main();
