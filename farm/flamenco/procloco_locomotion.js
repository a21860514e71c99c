// SPDX-License-Identifier: GPL-3.0-or-later
//
// ProcLoco job type for Flamenco 3: generate locomotion for a shot's rigs once, then
// render the shot in chunks of frames on any number of Workers.
//
// Install: copy this file into the `scripts/` folder beside the `flamenco-manager`
// executable and restart the Manager; the job type is then called `procloco-locomotion`
// (Flamenco names a job type after its file, `_` becoming `-`).
//
// Tasks of one job:
//   generate-locomotion   one task: opens the submitted .blend, runs ProcLoco's batch
//                         command over the whole frame range (the simulation is not
//                         chunked: every frame depends on the ones before it) and saves
//                         `<blend>-procloco.blend` beside the render output. The source
//                         file is never written. Needs ProcLoco installed on the Worker.
//   render-A-B            one task per chunk, each depending on generate-locomotion:
//                         Blender's own --render-frame on the generated file, with the
//                         scene's engine and settings. Needs only Blender.
//   preview-video         optional, after every render task: FFmpeg joins the frames.
//
// Runs in the Manager's JavaScript engine (goja, strict mode): no modules, no imports;
// only the globals Flamenco provides (author, path, frameChunker, shellSplit, print,
// formatTimestampLocal).

const JOB_TYPE = {
    label: "ProcLoco Locomotion",
    description: "Generate ProcLoco locomotion for the rigs of the shot, then render it in chunks",
    settings: [
        // What to generate.
        { key: "frames", type: "string", required: true,
          eval: "f'{C.scene.frame_start}-{C.scene.frame_end}'",
          evalInfo: { showLinkButton: true, description: "Scene frame range" },
          description: "Frames to generate and render, one contiguous range: '1-120', '1..120' or '47'" },
        { key: "chunk_size", type: "int32", default: 10, propargs: { min: 1 }, visible: "submission",
          description: "Number of frames one render task renders" },
        { key: "rigs", type: "string", default: "", visible: "submission",
          eval: "', '.join(o.name for o in C.selected_objects if o.type == 'ARMATURE')",
          evalInfo: { showLinkButton: true, description: "Selected armatures" },
          description: "Armatures to animate, separated by commas; empty: every armature of the scene" },
        { key: "bake_secondary", type: "bool", default: false, visible: "submission",
          description: "Then bake secondary motion (tails, antennae, ears) on the rigs that have or are suggested chains" },
        { key: "speed", type: "float", default: 0.0, propargs: { min: 0.0 }, visible: "submission",
          description: "Walking speed in metres per second for every rig; 0 keeps each rig's own" },
        { key: "seed", type: "int32", default: -1, propargs: { min: -1 }, visible: "submission",
          description: "Random seed for every rig; -1 keeps each rig's own" },
        { key: "procloco_args", type: "string", default: "", visible: "submission",
          description: "More 'procloco generate' options: --heading DEG, --step-height M, " +
                       "--spine / --no-spine, --visual-yaw / --no-visual-yaw" },

        // Where the output goes: render_output_root + add_path_components give render_output_path.
        { key: "render_output_root", type: "string", subtype: "dir_path", required: true, visible: "submission",
          description: "Folder for the output; job-specific folders are added below it" },
        { key: "add_path_components", type: "int32", required: true, default: 0,
          propargs: { min: 0, max: 32 }, visible: "submission",
          description: "Number of folders of the blend file's path to repeat in the output path" },
        { key: "render_output_path", type: "string", subtype: "file_path", editable: false,
          eval: "str(Path(abspath(settings.render_output_root), last_n_dir_parts(settings.add_path_components), jobname, '{timestamp}', '######'))",
          description: "Path of the rendered frames; the generated .blend is saved in the same folder" },
        { key: "make_video", type: "bool", default: true, visible: "submission",
          description: "Then join the frames into a preview video (FFmpeg on the Worker; not for EXR)" },

        // Filled in from the scene when submitting.
        { key: "blendfile", type: "string", required: true, visible: "web",
          description: "The shot's .blend file" },
        { key: "fps", type: "float", eval: "C.scene.render.fps / C.scene.render.fps_base", visible: "hidden" },
        { key: "format", type: "string", required: true, eval: "C.scene.render.image_settings.file_format",
          visible: "web", description: "Image format of the rendered frames" },
        { key: "image_file_extension", type: "string", required: true, eval: "C.scene.render.file_extension",
          visible: "hidden", description: "File extension of the rendered frames" },
    ],
};

// Formats that write one movie for the whole range: chunks rendered apart cannot be one movie.
const MOVIE_FORMATS = ["FFMPEG", "AVI_JPEG", "AVI_RAW"];
// Image formats FFmpeg does not read: no preview video for those.
const NO_VIDEO_FORMATS = ["EXR", "MULTILAYER", "OPEN_EXR", "OPEN_EXR_MULTILAYER"];

// Options of `procloco generate` a user may add in procloco_args, and what their value is.
const EXTRA_OPTIONS = {
    "--heading": "number",
    "--step-height": "length",
    "--spine": "",
    "--no-spine": "",
    "--visual-yaw": "",
    "--no-visual-yaw": "",
};
// Options the job itself passes, and the setting that controls them.
const JOB_OPTIONS = {
    "--rig": "rigs", "--rigs": "rigs", "--all": "rigs", "--frames": "frames",
    "--bake-secondary": "bake_secondary", "--no-bake-secondary": "bake_secondary",
    "--speed": "speed", "--seed": "seed", "--save": "render_output_root",
    "--render": "render_output_root", "--contact-sheet": "render_output_root",
    "--frame-step": "chunk_size", "--resolution": "the scene's own resolution",
};

function compileJob(job) {
    const settings = job.settings;
    const frames = contiguousRange(settings.frames);
    const chunkSize = wholeNumber(settings.chunk_size, "chunk_size", 1);
    const blendfile = checkedBlendfile(settings.blendfile);
    if (MOVIE_FORMATS.indexOf(settings.format) >= 0) {
        throw `The scene renders a movie (${settings.format}): set an image format (PNG, OPEN_EXR, ...) ` +
              "so that chunks can be rendered on different Workers";
    }
    const generateArgs = generateArguments(settings, frames);

    const renderOutput = renderOutputPath(job);
    settings.render_output_path = renderOutput;  // so the job shows the path really used
    const renderDir = path.dirname(renderOutput);
    const generated = path.join(renderDir, `${shotName(blendfile)}-procloco.blend`);

    const generateTask = author.Task("generate-locomotion", "blender");
    generateTask.addCommand(author.Command("blender-render", {
        exe: "{blender}",
        exeArgs: "{blenderArgs}",
        argsBefore: [],
        blendfile: blendfile,
        args: generateArgs.concat(["--save", generated]),
    }));
    job.addTask(generateTask);

    const renderTasks = [];
    for (const chunk of frameChunker(frames.text, chunkSize)) {
        const task = author.Task(`render-${chunk}`, "blender");
        task.addCommand(author.Command("blender-render", {
            exe: "{blender}",
            exeArgs: "{blenderArgs}",
            argsBefore: [],
            blendfile: generated,
            args: [
                "--render-output", renderOutput,
                "--render-format", settings.format,
                "--render-frame", chunk.split("-").join(".."),  // Blender writes a range A..B
            ],
        }));
        task.addDependency(generateTask);
        job.addTask(task);
        renderTasks.push(task);
    }

    const videoTask = previewVideoTask(settings, frames, renderDir, blendfile);
    if (videoTask) {
        for (const task of renderTasks) {
            videoTask.addDependency(task);
        }
        job.addTask(videoTask);
    }
}

// The frame range as {first, last, text}; one contiguous range, because the simulation of
// a frame starts from the one before it.
function contiguousRange(value) {
    const text = String(value === undefined || value === null ? "" : value).trim();
    if (text === "") {
        throw "frames: give the frame range to generate and render, for example '1-120'";
    }
    if (text.indexOf(",") >= 0) {
        throw `frames: '${text}' is not one contiguous range; the locomotion is simulated frame after ` +
              "frame over one range: submit one job per range";
    }
    const match = /^(-?\d+)(?:\s*(?:\.\.|-)\s*(-?\d+))?$/.exec(text);
    if (!match) {
        throw `frames: '${text}' is not a frame range; write START-END, START..END or one frame`;
    }
    const first = parseInt(match[1], 10);
    const last = match[2] === undefined ? first : parseInt(match[2], 10);
    if (first < 0 || last < 0) {
        throw `frames: '${text}' has a negative frame; Flamenco's frame ranges start at 0`;
    }
    if (last < first) {
        throw `frames: '${text}' is reversed; the first frame comes first`;
    }
    return { first: first, last: last, text: first === last ? `${first}` : `${first}-${last}` };
}

function wholeNumber(value, key, minimum) {
    const number = Number(value);
    if (value === "" || value === null || value === undefined || !isFinite(number) ||
        Math.floor(number) !== number) {
        throw `${key}: '${value}' is not a whole number`;
    }
    if (number < minimum) {
        throw `${key}: ${number} is too small; the least is ${minimum}`;
    }
    return number;
}

function checkedBlendfile(value) {
    const file = String(value === undefined || value === null ? "" : value).trim();
    if (file === "") {
        throw "blendfile: no .blend file given; submit the job from Blender with Flamenco's add-on";
    }
    if (!/\.blend$/i.test(file)) {
        throw `blendfile: '${file}' is not a .blend file`;
    }
    return file;
}

// Name of the shot: the blend file's name without `.blend` and without the `.flamenco`
// that the add-on adds to the copy it submits.
function shotName(blendfile) {
    return path.stem(blendfile).replace(/\.flamenco$/, "");
}

// The arguments after the blend file for the generate task (without --save).
function generateArguments(settings, frames) {
    const args = ["--command", "procloco", "generate"];
    const rigs = String(settings.rigs || "").split(",").map((name) => name.trim());
    const named = rigs.filter((name) => name !== "");
    if (named.length === 0) {
        args.push("--all");
    } else {
        if (named.length !== rigs.length) {
            throw `rigs: '${settings.rigs}' has an empty name between commas`;
        }
        for (const name of named) {
            args.push("--rig", name);
        }
    }
    args.push("--frames", `${frames.first}`, `${frames.last}`);
    if (settings.bake_secondary) {
        args.push("--bake-secondary");
    }
    const speed = Number(settings.speed || 0);
    if (!isFinite(speed) || speed < 0) {
        throw `speed: '${settings.speed}' is not a speed in metres per second (0 keeps each rig's own)`;
    }
    if (speed > 0) {
        args.push("--speed", `${speed}`);
    }
    const seed = wholeNumber(settings.seed === undefined ? -1 : settings.seed, "seed", -1);
    if (seed >= 0) {
        args.push("--seed", `${seed}`);
    }
    return args.concat(extraArguments(settings.procloco_args));
}

// procloco_args split like a shell would, each option checked here so that a typo fails
// when the job is submitted rather than on a Worker.
function extraArguments(text) {
    const words = text ? shellSplit(String(text)) : [];
    const args = [];
    for (let i = 0; i < words.length; i++) {
        const word = words[i];
        const option = word.split("=")[0];
        if (JOB_OPTIONS.hasOwnProperty(option)) {
            throw `procloco_args: ${option} is set by the job; use the '${JOB_OPTIONS[option]}' setting`;
        }
        if (!EXTRA_OPTIONS.hasOwnProperty(word)) {
            throw `procloco_args: '${word}' is not one of ${Object.keys(EXTRA_OPTIONS).join(", ")}` +
                  " (an option and its value are two words: --heading 30)";
        }
        args.push(word);
        const kind = EXTRA_OPTIONS[word];
        if (kind === "") {
            continue;
        }
        const value = words[i + 1];
        const number = Number(value);
        if (value === undefined || value.trim() === "" || !isFinite(number) || (kind === "length" && number < 0)) {
            throw `procloco_args: ${word} needs a ${kind === "length" ? "length in metres" : "number"}, ` +
                  `not '${value === undefined ? "" : value}'`;
        }
        args.push(value);
        i++;
    }
    return args;
}

function renderOutputPath(job) {
    const output = job.settings.render_output_path;
    if (!output) {
        throw "render_output_path: no output path; set render_output_root";
    }
    return String(output).replace(/{timestamp}/g, () => formatTimestampLocal(job.created));
}

function previewVideoTask(settings, frames, renderDir, blendfile) {
    if (!settings.make_video) {
        return null;
    }
    if (NO_VIDEO_FORMATS.indexOf(settings.format) >= 0) {
        print(`No preview video: FFmpeg does not read ${settings.format} frames`);
        return null;
    }
    const fps = Number(settings.fps);
    if (!settings.fps || !isFinite(fps) || fps <= 0) {
        print("No preview video: the frame rate is unknown");
        return null;
    }
    const task = author.Task("preview-video", "ffmpeg");
    task.addCommand(author.Command("frames-to-video", {
        exe: "ffmpeg",
        fps: fps,
        inputGlob: path.join(renderDir, `*${settings.image_file_extension}`),
        outputFile: path.join(renderDir, `${shotName(blendfile)}-${frames.text}.mp4`),
        args: ["-c:v", "h264", "-crf", "20", "-vf", "pad=ceil(iw/2)*2:ceil(ih/2)*2", "-pix_fmt", "yuv420p", "-y"],
    }));
    return task;
}
